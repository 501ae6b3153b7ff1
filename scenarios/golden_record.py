"""The golden record's file and its comparison: what a record holds and where it was made, reading it back, and
what differs between a record and a fresh run (``scenarios.golden`` runs the episodes)."""

from __future__ import annotations

import dataclasses
import importlib.metadata
import json
import platform
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

PROG = "python -m scenarios.golden"
FORMAT = 1
#: the record files of the two subsets (relative to the repository root)
DEFAULT_PATHS: dict[str, Path] = {"full": Path("tests/golden/record.json"), "ci": Path("tests/golden/record_ci.json")}
SOURCES: tuple[str, ...] = ("expert", "policy")
TARGETS: tuple[str, ...] = ("static", "linear", "reversal", "jump")
SEEDS: tuple[int, ...] = (0, 1, 2)
#: the tick orders: simulated (``EpisodeRunner`` without a deadline) and deadline (real time's order, simulated time)
SIMULATED_ORDER, DEADLINE_ORDER = "simulated", "deadline"
#: figures of ``episode_metrics`` that are wall-clock timings (or per-tick lists of them): they change from run to
#: run and are not recorded
WALL_CLOCK_KEYS: frozenset[str] = frozenset({
    "tick_us_median", "tick_us_p99", "mpc_solve_us_median", "mpc_solve_us_p99", "mpc_solve_us",
    "plan_ms_median", "plan_ms", "source_timing_ms", "sensor_ms_per_sim_s", "realtime_factor",
    # real time's deadline statistics (absent in simulated time; listed so a record never holds them)
    "realtime", "overruns", "overrun_rate", "cycles_missed", "late_commands", "exec_us_median", "exec_us_p99",
    "exec_us_max", "jitter_us_std", "jitter_us_p99", "control_command_success_rate", "realtime_rate", "exec_us",
    "late_ticks",
})
#: the libraries whose versions can move the last bits of a result (distribution names)
LIBRARIES: tuple[str, ...] = ("numpy", "mujoco", "pin", "osqp", "torch", "numba")


# ---- the record ---------------------------------------------------------------------------------------------------
def made_with() -> dict:
    """Where the hashes are made: library versions, CPU model, Python, the git commit (best effort)."""
    versions = {}
    for name in LIBRARIES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    cpu = next((line.split(":", 1)[1].strip() for line in _read_lines("/proc/cpuinfo")
                if line.startswith("model name")), platform.processor() or None)
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10,
                                cwd=Path(__file__).resolve().parent).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        commit = None
    return {"versions": versions, "cpu_model": cpu, "python": platform.python_version(),
            "machine": platform.machine(), "git_commit": commit}


def _read_lines(path: str) -> list[str]:
    try:
        return Path(path).read_text().splitlines()
    except OSError:
        return []


def make_record(subset: str, cells: tuple, episodes: dict[str, dict]) -> dict:
    """The record's JSON payload."""
    return {"format": FORMAT, "subset": subset, "made_with": made_with(),
            "dropped_figures": sorted(WALL_CLOCK_KEYS),
            "cells": [dataclasses.asdict(c) for c in cells], "episodes": episodes}


def host_record_path(path: Path, cpu_model: str | None = None) -> Path:
    """The record for this host's CPU beside ``path``: ``path`` itself when it was made on this CPU model (or does not
    exist yet), else its sibling named for the CPU (``record_ci.json`` -> ``record_ci.<cpu>.json``). A CPU can move the
    last bits where no variable pins them (measured 2026-12-06: the CI subset's three policy episodes differ between
    an AMD EPYC and an Intel Xeon with OpenBLAS pinned, MKL's and oneDNN's ISA pinned, numpy's AVX-512 paths off and
    llvmpipe at 256 bits; the expert's episodes agree), so each kind of host keeps its own record, and a change is
    checked against the record of the host it runs on."""
    path = Path(path)
    cpu = made_with()["cpu_model"] if cpu_model is None else cpu_model
    try:
        own = json.loads(path.read_text()).get("made_with", {}).get("cpu_model") == cpu
    except (OSError, ValueError, AttributeError):
        own = True  # absent or unreadable: the path as given (load_record says what is wrong)
    if own or not cpu:
        return path
    slug = re.sub(r"[^a-z0-9]+", "-", cpu.lower()).strip("-")
    return path.with_name(f"{path.stem}.{slug}{path.suffix}")


def cpu_isa() -> str:
    """The widest vector instruction set this CPU offers (``avx512``, ``avx2`` or ``base``), from /proc/cpuinfo."""
    flags = next((line.split(":", 1)[1].split() for line in _read_lines("/proc/cpuinfo") if line.startswith("flags")), [])
    return "avx512" if "avx512f" in flags else "avx2" if "avx2" in flags else "base"


def isa_record_path(path: Path, cpu_model: str | None = None, isa: str | None = None) -> Path:
    """The record for this CPU model *and* vector instruction set beside ``path`` (``record_ci.json`` ->
    ``record_ci.<cpu>.<isa>.json``): two hosts may report the same model name and still dispatch torch's kernels
    differently (measured 2026-12-07: on an "AMD EPYC" without AVX-512 the 72 policy episodes of the full record
    differ in their last bits from the "AMD EPYC" host the default record was made on, the code before and after the
    day's change alike; the 73 expert episodes agree)."""
    path = Path(path)
    cpu = made_with()["cpu_model"] if cpu_model is None else cpu_model
    slug = re.sub(r"[^a-z0-9]+", "-", (cpu or "cpu").lower()).strip("-")
    return path.with_name(f"{path.stem}.{slug}.{isa or cpu_isa()}{path.suffix}")


def record_to_check(path: Path) -> Path:
    """The record a check on this host compares with: its CPU model's and instruction set's
    (:func:`isa_record_path`) where there is one, else its CPU model's (:func:`host_record_path`), else ``path``
    (the report's note then says the record was made elsewhere)."""
    fine = isa_record_path(path)
    if fine.exists():
        return fine
    own = host_record_path(path)
    return own if own.exists() else Path(path)


def load_record(path: Path) -> dict:
    """The record at ``path``; ValueError (one line) when it is missing or malformed."""
    try:
        record = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ValueError(f"no record at {str(path)!r} (make one with {PROG} --write)") from None
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"cannot read the record {str(path)!r}: {exc}") from None
    if not isinstance(record, dict) or record.get("format") != FORMAT:
        raise ValueError(f"{str(path)!r} is not a golden record of format {FORMAT}")
    if not isinstance(record.get("cells"), list) or not isinstance(record.get("episodes"), dict):
        raise ValueError(f"{str(path)!r} is not a golden record: it needs 'cells' (a list) and 'episodes' (a dict)")
    return record


# ---- comparing ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Difference:
    """One episode that does not reproduce its record.

    Attributes:
        key: the episode (``Cell.key``).
        figures: (name, recorded, now) of each figure that changed, as JSON text (``absent`` where one is missing).
        tau_changed: the torque commands' hash changed.
        ee_changed: the TCP path's hash changed.
        note: what else differs (skipped before and run now, in the record and not run, ...).
    """

    key: str
    figures: tuple[tuple[str, str, str], ...] = ()
    tau_changed: bool = False
    ee_changed: bool = False
    note: str = ""


def _text(value) -> str:
    """A figure as JSON text: equal text is equal bits (floats print their shortest exact repr; NaN is NaN)."""
    return json.dumps(value, sort_keys=True)


def compare_episode(key: str, old: dict, new: dict) -> Difference | None:
    """The difference between one episode's recorded and fresh entries, None when identical. Figures only the fresh
    run has (a figure added since) are not compared: they moved nothing that was recorded."""
    if "error" in new:
        return Difference(key, note=f"raised {new['error']}")
    if "skipped" in old or "skipped" in new:
        if old.get("skipped") == new.get("skipped"):
            return None
        note = (f"skipped in the record ({old['skipped']}), runs now" if "skipped" in old else
                f"recorded, skipped now ({new['skipped']})" if "skipped" not in old and "skipped" in new else
                f"skipped for another reason now: {new['skipped']}")
        return Difference(key, note=note)
    old_figures, new_figures = {"ticks": old.get("ticks"), **old.get("figures", {})}, \
        {"ticks": new.get("ticks"), **new.get("figures", {})}
    changed = tuple((name, _text(value), _text(new_figures[name]) if name in new_figures else "absent")
                    for name, value in old_figures.items()
                    if name not in new_figures or _text(value) != _text(new_figures[name]))
    tau = old.get("tau_cmd_sha256") != new.get("tau_cmd_sha256")
    ee = old.get("ee_pos_sha256") != new.get("ee_pos_sha256")
    return Difference(key, changed, tau, ee) if changed or tau or ee else None


def compare(recorded: dict[str, dict], fresh: dict[str, dict]) -> list[Difference]:
    """Every episode whose fresh entry differs from its recorded one (and those only one side has)."""
    diffs = [Difference(key, note="in the record, not run now") for key in recorded if key not in fresh]
    diffs += [Difference(key, note="run now, not in the record") for key in fresh if key not in recorded]
    for key in recorded.keys() & fresh.keys():
        diff = compare_episode(key, recorded[key], fresh[key])
        if diff is not None:
            diffs.append(diff)
    order = {key: i for i, key in enumerate(list(recorded) + list(fresh))}
    return sorted(diffs, key=lambda d: order[d.key])


def format_report(diffs: list[Difference], record: dict, path: Path) -> str:
    """The check's report: each differing episode's changed figures (recorded -> now) and hashes, then a total."""
    episodes = record["episodes"]
    skipped = sum("skipped" in e for e in episodes.values() if isinstance(e, dict))
    lines = []
    for d in diffs:
        hits = (("torque", d.tau_changed), ("TCP path", d.ee_changed))
        hashes = [f"{what} hash changed" for what, hit in hits if hit]
        if not hashes and not d.note:
            hashes = ["hashes unchanged"]
        lines.append(f"DIFF {d.key}: " + ", ".join(([d.note] if d.note else []) + hashes))
        lines += [f"    {name}: {old} -> {new}" for name, old, new in d.figures]
    if diffs:
        lines.append(f"{len(diffs)} of {len(episodes)} episodes differ from {path}")
    else:
        lines.append(f"all {len(episodes)} episodes identical to {path} ({skipped} skipped, as recorded)")
    now = made_with()
    where = [f"{k}: {record.get('made_with', {}).get(k)!r} then, {now[k]!r} now" for k in ("versions", "cpu_model")
             if record.get("made_with", {}).get(k) != now[k]]
    if where:
        lines.append("note: the record was made elsewhere (" + "; ".join(where) + "); the last bits may differ")
    return "\n".join(lines)
