"""The sweep report on synthetic rows: tables with Wilson intervals, paired verdicts, figures."""

import math

import numpy as np

from mmact_ctrl.stats import wilson_interval
from scenarios.sweep.report import write_report

MODES = ("open_loop", "receding", "temporal_ensemble", "inpaint", "residual", "hybrid")
N = 10


def _row(rng, study, mode, seed, success, err=None, **axes):
    base = dict(study=study, mode=mode, seed=seed, source="expert", lead="velocity", target="linear", speed_m_s=0.3,
                replan_hz=1.0, latency_ms=200.0, d_steps=2, s_steps=None, bins=2048, perception="oracle")
    err = err if err is not None else (0.02 if success else 0.15) + 0.01 * rng.random()
    return {**base, **axes, "success": bool(success), "final_error_m": err, "mean_error_m": 1.5 * err,
            "tracking_ratio": rng.random(), "reaction_s": float(rng.uniform(0.1, 0.6)) if rng.random() > 0.2
            else float("nan"), "reach_after_change_s": float("nan"), "d_measured": 2.0, "limit_violations": 0,
            "chunk_jump_acc_m_s2": float(rng.uniform(2, 10)), "jerk_rms": 1.0}


def _rows():
    rng = np.random.default_rng(0)
    rows = []
    # replan: hybrid 10/10 vs every baseline 0/10 at 1 Hz; at 5 Hz every mode 5/10 on the same seeds
    for mode in MODES:
        for hz in (1.0, 5.0):
            for s in range(N):
                ok = (mode == "hybrid") if hz == 1.0 else s < 5
                err = None if hz == 1.0 else 0.05 + 0.001 * s  # identical per seed: no error difference either
                rows.append(_row(rng, "replan", mode, s, ok, err, replan_hz=hz))
    # known cell: open_loop at 2 Hz succeeds on 7 of 10 seeds
    for s in range(N):
        rows.append(_row(rng, "replan", "open_loop", s, s < 7, replan_hz=2.0))
    # families with a second source (the policy, lead "-")
    for src, lead in (("expert", "velocity"), ("policy", "-")):
        for mode in MODES:
            for tg in ("reversal", "swerve"):
                for hz in (1.0, 5.0):
                    for s in range(N):
                        rows.append(_row(rng, "families", mode, s, rng.random() < (0.8 if mode == "hybrid" else 0.4),
                                         source=src, lead=lead, target=tg, replan_hz=hz, d_steps=None))
    # the d x s grid, with a cell past the chunk horizon
    for mode in ("open_loop", "hybrid"):
        for d in (0, 2, 16):
            for sh in (4, 8):
                for s in range(3):
                    rows.append(_row(rng, "rtc_grid", mode, s, d < 16 and (mode == "hybrid" or s == 0), d_steps=d,
                                     s_steps=sh))
    # an unknown study, and a row missing most keys
    for mode in ("open_loop", "hybrid"):
        rows.append(_row(rng, "mystery", mode, 0, True, target="circle"))
    rows.append({"study": "replan", "mode": "hybrid", "success": True})
    return rows


def test_report_has_intervals_verdicts_and_figures(tmp_path):
    write_report(_rows(), tmp_path, wall_s=12.0, resumed=3)
    text = (tmp_path / "report.md").read_text()
    for needle in ("## replan", "## families", "## rtc_grid", "## mystery", "expert", "policy", "How to read",
                   "not corrected for multiple comparisons", "Where the control layer adds nothing",
                   "residual vs open_loop"):
        assert needle in text, needle
    lo, hi = wilson_interval(7, 10)
    assert f"70% [{100 * lo:.0f}–{100 * hi:.0f}]" in text  # the open_loop 2 Hz cell
    lo, hi = wilson_interval(10, 10)
    assert f"100% [{100 * lo:.0f}–100]" in text
    lines = [ln for ln in text.splitlines() if ln.startswith("| ") and "10/10 vs 0/10" in ln]
    assert lines and all("hybrid better" in ln for ln in lines)  # 10/10 vs 0/10 on the same seeds
    lines = [ln for ln in text.splitlines() if ln.startswith("| ") and "5/10 vs 5/10" in ln]
    assert lines and all("no significant difference (p >= 0.05)" in ln for ln in lines)
    # the 5 Hz replan condition is listed where the control layer adds nothing
    nothing = text.split("Where the control layer adds nothing")[1]
    assert "replan: 5 Hz" in nothing
    for png in ("replan.png", "rtc_grid.png", "reaction.png", "chunk_jumps.png"):
        assert (tmp_path / png).stat().st_size > 5000, png
        assert f"({png})" in text


def test_report_survives_sparse_rows(tmp_path):
    rows = [{"study": "bins", "mode": "open_loop", "bins": b, "seed": s, "success": True, "final_error_m": 0.001}
            for b in (64, 0) for s in range(2)]
    rows += [{"study": "speed", "mode": "hybrid", "speed_m_s": 0.2, "seed": 0, "success": float("nan")}]
    write_report(rows, tmp_path, wall_s=1.0, resumed=0)
    text = (tmp_path / "report.md").read_text()
    assert "## bins" in text and "| none |" in text and (tmp_path / "bins.png").is_file()
    assert not math.isnan(len(text))
    write_report([], tmp_path / "empty", wall_s=0.0, resumed=0)
    assert "0 episodes" in (tmp_path / "empty" / "report.md").read_text()
