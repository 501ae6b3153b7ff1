"""The golden record (``scenarios.golden``): the CI subset reproduces its record bit for bit, and a record that does
not match (one figure one ulp off, a torque hash, an episode missing) is reported as a difference."""

import copy
import json
import math
from pathlib import Path

import pytest

from scenarios import golden

#: this host's CPU's record where it has one (``golden.host_record_path``), else the default one
RECORD_CI = golden.record_to_check(Path(__file__).parent / "golden" / "record_ci.json")


@pytest.fixture(scope="module")
def record():
    return golden.load_record(RECORD_CI)


@pytest.fixture(scope="module")
def fresh(record):
    """The CI subset's episodes run now, in this process (under 10 s here)."""
    return golden.run_cells(golden.record_cells(record), jobs=1, progress=False)


def test_the_ci_subset_reproduces_its_record_bit_for_bit(record, fresh):
    diffs = golden.compare(record["episodes"], fresh)
    assert diffs == [], golden.format_report(diffs, record, RECORD_CI)
    keys = list(record["episodes"])
    assert len(keys) == 6 and all("skipped" not in e for e in record["episodes"].values())
    for part in ("expert/", "policy/", "/open_loop/", "/hybrid/", "/linear/", "/jump/", "/deadline/"):
        assert any(part in k for k in keys), part  # the subset covers what it says it does


def test_a_figure_one_ulp_off_is_reported_with_exit_1(record, fresh, tmp_path, monkeypatch, capsys):
    perturbed = copy.deepcopy(record)
    key = next(iter(perturbed["episodes"]))
    figures = perturbed["episodes"][key]["figures"]
    old = figures["final_error_m"]
    figures["final_error_m"] = math.nextafter(old, math.inf)
    path = tmp_path / "record.json"
    path.write_text(json.dumps(perturbed))
    monkeypatch.setattr(golden, "run_cells", lambda cells, jobs=2, progress=True: fresh)  # the episodes run above
    assert golden.main(["--check", str(path), "--jobs", "1", "--quiet"]) == 1
    out = capsys.readouterr().out
    assert f"DIFF {key}: hashes unchanged" in out
    assert f"final_error_m: {figures['final_error_m']!r} -> {old!r}" in out
    assert f"1 of 6 episodes differ from {path}" in out
    monkeypatch.setattr(golden, "run_cells", lambda cells, jobs=2, progress=True: copy.deepcopy(fresh))
    assert golden.main(["--check", str(RECORD_CI), "--quiet"]) == 0  # the record itself: identical, exit 0
    assert "all 6 episodes identical" in capsys.readouterr().out


def test_a_torque_hash_a_missing_episode_and_a_skip_are_differences(record, fresh):
    now = copy.deepcopy(fresh)
    first, second, third = list(now)[:3]
    now[first]["tau_cmd_sha256"] = "0" * 64
    del now[second]
    now[third] = {"skipped": "source 'x' cannot run --mode hybrid"}
    diffs = {d.key: d for d in golden.compare(record["episodes"], now)}
    assert set(diffs) == {first, second, third}
    assert diffs[first].tau_changed and not diffs[first].ee_changed and diffs[first].figures == ()
    assert diffs[second].note == "in the record, not run now"
    assert diffs[third].note.startswith("recorded, skipped now")
    report = golden.format_report(list(diffs.values()), record, RECORD_CI)
    assert f"DIFF {first}: torque hash changed" in report and "3 of 6 episodes differ" in report


def test_a_figure_added_since_the_record_is_not_a_difference(record, fresh):
    now = copy.deepcopy(fresh)
    for entry in now.values():
        entry["figures"]["a_new_figure"] = 1.0
    assert golden.compare(record["episodes"], now) == []


@pytest.mark.parametrize("content, needle", [
    (None, "no record at"),
    ("{not json", "cannot read the record"),
    ('{"format": 99}', "is not a golden record"),
    ('{"format": 1, "cells": [{"source": "expert"}], "episodes": {}}', "a malformed cell"),
])
def test_bad_input_is_one_line_and_exit_2(content, needle, tmp_path, capsys, one_line_exit_2):
    path = tmp_path / "record.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(SystemExit) as exc:
        golden.main(["--check", str(path)])
    one_line_exit_2(exc.value.code, capsys.readouterr().err, needle)


def test_bad_arguments_are_one_line_and_exit_2(capsys, one_line_exit_2):
    with pytest.raises(SystemExit) as exc:
        golden.main(["--check", "--jobs", "0"])
    one_line_exit_2(exc.value.code, capsys.readouterr().err, "--jobs")


def test_each_cpu_model_checks_against_its_own_record(tmp_path):
    path = tmp_path / "record_ci.json"
    assert golden.host_record_path(path, "AMD EPYC") == path  # no record yet: the default path
    path.write_text(json.dumps({"made_with": {"cpu_model": "AMD EPYC"}}))
    assert golden.host_record_path(path, "AMD EPYC") == path
    assert golden.host_record_path(path, "Intel(R) Xeon(R) Processor") == tmp_path / "record_ci.intel-r-xeon-r-processor.json"


def test_a_host_with_the_same_model_name_and_another_instruction_set_checks_against_its_own_record(tmp_path,
                                                                                                   monkeypatch):
    from scenarios import golden_record

    path = tmp_path / "record_ci.json"
    path.write_text(json.dumps({"made_with": {"cpu_model": "AMD EPYC"}}))
    fine = golden_record.isa_record_path(path, "AMD EPYC", "avx2")
    assert fine == tmp_path / "record_ci.amd-epyc.avx2.json"
    monkeypatch.setattr(golden_record, "isa_record_path", lambda p: golden_record.Path(p).with_name(fine.name))
    monkeypatch.setattr(golden_record, "host_record_path", lambda p: golden_record.Path(p))
    assert golden_record.record_to_check(path) == path  # no record for the instruction set yet: the model's
    fine.write_text("{}")
    assert golden_record.record_to_check(path) == fine
