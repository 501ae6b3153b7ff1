"""The fault suite's findings in words: what the faults cost versus the ``none`` row, and the totals."""

from __future__ import annotations

import numpy as np

from scenarios.faults.injectors import FAULTS


def costs_paragraph(costs: dict, recovery: dict | None = None) -> str:
    """Plain language, computed: which faults cost success (and recovery after the fault window) and how much
    versus the ``none`` row."""
    paras = []
    for src, c in costs.items():
        if not c["baseline"]:
            paras.append(f"**{src}**: no `none` baseline in this run, so no fault's cost can be computed.")
            continue
        text = _cost_sentences(c, "succeeds (within 3 cm for 0.3 s at any time of the episode)", "success")
        if recovery is not None and src in recovery and recovery[src]["baseline"]:
            text += " " + _cost_sentences(recovery[src], "is back on the target after the fault window (within 3 cm "
                                                         "for 0.3 s; from the onset without a fault)", "recovery")
        paras.append(f"**{src}**: " + text)
    return "\n\n".join(paras)


def _cost_sentences(c: dict, what: str, noun: str) -> str:
    base = c["baseline"]
    parts = [f"Without a fault the TCP {what} in {np.mean(list(base.values())):.0%} of episodes ("
             + ", ".join(f"{m} {v:.0%}" for m, v in base.items()) + ")."]
    costly = sorted(((f, d) for f, d in c["faults"].items() if d["delta"] < -1e-9), key=lambda x: x[1]["delta"])
    better = [f for f, d in c["faults"].items() if d["delta"] > 1e-9]
    free = [f for f, d in c["faults"].items() if abs(d["delta"]) <= 1e-9]
    if costly:
        items = []
        for f, d in costly:
            note = " (expected: the target is out of reach)" if FAULTS[f].unreachable else ""
            items.append(f"`{f}` {100 * d['delta']:+.0f} points ({d['baseline']:.0%} -> {d['rate']:.0%} over "
                         f"{d['n_modes']} mode{'s' if d['n_modes'] > 1 else ''}; "
                         f"worst in {d['worst_mode']}: {d['worst_baseline']:.0%} -> {d['worst_rate']:.0%}){note}")
        parts.append(f"{len(costly)} fault(s) cost {noun}: " + "; ".join(items) + ".")
    else:
        parts.append(f"No fault cost {noun}.")
    if free:
        parts.append(f"No loss of {noun} with {len(free)} fault(s): " + ", ".join(f"`{f}`" for f in free) + ".")
    if better:
        parts.append(f"More {noun} than the baseline (seed noise, or a fault that happens to help): "
                     + ", ".join(f"`{f}`" for f in better) + ".")
    return " ".join(parts)


def totals_text(t: dict) -> str:
    lines = [f"- episodes: {t['episodes']}",
             "- violations: " + ", ".join(f"{k} {v}" for k, v in t["violations"].items())]
    if t["violation_cells"]:
        lines.append("- violations came from: " + ", ".join(f"{c['fault']}/{c['mode']}/{c['source']}"
                                                            for c in t["violation_cells"]))
    lines.append(f"- exceptions escaping run_episode: {t['exceptions']}")
    for e in t["exception_list"]:
        lines.append(f"  - {e['fault']}/{e['mode']}/{e['source']} seed {e['seed']}: {e['raised']}")
    by_fault: dict[str, int] = {}
    for a in t["abort_list"]:
        by_fault[a["fault"]] = by_fault.get(a["fault"], 0) + 1
    lines.append(f"- aborts: {t['aborts']} (" + (", ".join(f"{f} x{n}" for f, n in by_fault.items()) or "none")
                 + f"; unexpected: {t['unexpected_aborts']})")
    if t["missing_expected_aborts"]:
        lines.append("- expected aborts that did not happen: " + ", ".join(
            f"{a['fault']}/{a['mode']}/{a['source']} seed {a['seed']}" for a in t["missing_expected_aborts"]))
    lines.append("- faults survived: " + ", ".join(f"{k} {t[k]}" for k in (
        "rejected_chunks", "watchdog_stops", "gated_measurements", "missed_ticks", "qp_failures", "mpc_failures",
        "perception_errors")))
    return "\n".join(lines)
