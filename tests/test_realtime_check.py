"""``scenarios.realtime_check``: its verdicts, its report and the settings both sides share (no real-time run here;
tests/test_realtime.py runs the loop on the wall clock)."""

import argparse

from scenarios.realtime_check import NEGLIGIBLE_FINAL_MM, _verdict, report


def _row(**kw) -> dict:
    row = {"mode": "hybrid", "n": 10, "real_success": 10, "real_ci95": [0.72, 1.0], "sim_success": 10,
           "sim_ci95": [0.72, 1.0], "diff_success": 0.0, "diff_lo": -0.28, "diff_hi": 0.28, "p_mcnemar": 1.0,
           "real_final_mm": 5.0, "sim_final_mm": 5.0, "diff_final_mm": 0.0, "diff_final_lo_mm": -0.1,
           "diff_final_hi_mm": 0.1, "p_wilcoxon": 0.9, "round_trip_ms": {"median": 2.5, "p95": 3.0, "max": 4.0},
           "d_steps": {"median": 0.04, "max": 0.06}, "overruns": 0, "overrun_rate": 0.0,
           "control_command_success_rate": 1.0, "violations": 0, "sim_violations": 0}
    row.update(kw)
    return row


def test_verdicts_need_significance_and_a_difference_that_matters():
    assert _verdict(_row()) == "no significant difference"
    assert "optimistic** (success)" in _verdict(_row(diff_success=-0.6, p_mcnemar=0.03))
    assert "real time is better (success)" == _verdict(_row(diff_success=0.6, p_mcnemar=0.03))
    assert "optimistic** (final error)" in _verdict(_row(diff_final_mm=4.0, p_wilcoxon=0.01))
    assert "real time is better (final error)" == _verdict(_row(diff_final_mm=-4.0, p_wilcoxon=0.01))
    # float rounding between two identical runs: every difference of one sign, so a rank test calls it significant
    tiny = _verdict(_row(diff_final_mm=2e-5, p_wilcoxon=0.037))
    assert tiny.startswith("significant but negligible") and "optimistic" not in tiny
    assert "optimistic" in _verdict(_row(diff_final_mm=NEGLIGIBLE_FINAL_MM + 0.01, p_wilcoxon=0.04))


def test_report_lists_only_the_cells_where_simulation_is_optimistic():
    args = argparse.Namespace(source="expert", modes=["inpaint", "hybrid"], episodes=10, duration_s=6.0,
                              replan_hz=1.0, speed=0.2, qp_max_iter=100)
    results = {"reversal": {"latency_ms": 2.5, "rows": [_row(mode="inpaint", diff_final_mm=2e-5, p_wilcoxon=0.037),
                                                        _row(mode="hybrid", diff_final_mm=6.0, p_wilcoxon=0.01)]}}
    text = report(results, args)
    assert "QP's iteration cap 100" in text
    tail = text.split("## Where the simulated-latency figures are optimistic")[1]
    assert "hybrid on reversal" in tail and "inpaint" not in tail


def test_both_sides_of_the_check_run_with_the_real_time_qp_cap():
    from scenarios.moving_target import stack_config
    from scenarios.realtime_check import _main_job_args, build_parser

    args = build_parser().parse_args(["--out", "unused", "--modes", "hybrid"])
    real = _main_job_args(args, "linear", realtime=True)
    sim = _main_job_args(args, "linear", realtime=False, latency_ms=2.5)
    assert stack_config(real, "hybrid").qp.max_iter == stack_config(sim, "hybrid").qp.max_iter == 100


def test_qp_cap_defaults_to_100_in_real_time_and_400_in_simulated_time():
    from controllers.qp_id import QPConfig
    from scenarios.moving_target import build_parser, stack_config

    parser = build_parser()
    assert stack_config(parser.parse_args([]), "hybrid").qp.max_iter == QPConfig().max_iter == 400
    assert stack_config(parser.parse_args(["--realtime"]), "hybrid").qp.max_iter == 100
    assert stack_config(parser.parse_args(["--qp-max-iter", "37"]), "hybrid").qp.max_iter == 37
