"""The sweep report's data handling and Markdown tables: per-study success tables with Wilson
intervals, and paired (same-seed) comparisons of two modes with their verdicts.

Rows are one per episode (see ``scenarios.sweep``); every key is optional here: a missing axis is
``None`` (shown as "-"), a missing source is "expert", a missing metric is NaN.
"""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np

from mmact_ctrl.stats import paired_binary, paired_continuous, wilson_interval

ALPHA = 0.05
MODE_ORDER = ("open_loop", "receding", "temporal_ensemble", "inpaint", "residual", "hybrid")
ORDERS = {
    "mode": MODE_ORDER,
    "source": ("expert", "policy"),
    "lead": ("velocity", "none", "-"),
    "target": ("static", "linear", "circle", "random_walk", "jump", "reversal", "accelerating", "swerve"),
    "perception": ("oracle", "camera"),
}
# the axes that define a condition (with study and mode); episodes of one condition differ by seed only
COND_AXES = ("source", "lead", "target", "speed_m_s", "replan_hz", "latency_ms", "d_steps", "s_steps", "bins",
             "perception", "task", "clearance_mm", "noise_m", "compliance", "close_at_grasp")
HEAD = {"source": "source", "lead": "lead", "target": "target", "speed_m_s": "speed [m/s]", "replan_hz": "replan [Hz]",
        "latency_ms": "latency [ms]", "d_steps": "d [steps]", "s_steps": "s [steps]", "bins": "bins",
        "perception": "perception", "task": "task", "clearance_mm": "clearance [mm]", "noise_m": "noise [m]",
        "compliance": "compliance", "close_at_grasp": "close at grasp"}
UNIT = {"speed_m_s": " m/s", "replan_hz": " Hz", "latency_ms": " ms", "clearance_mm": " mm", "noise_m": " m"}
PREFIX = {"lead": "lead ", "d_steps": "d=", "s_steps": "s=", "bins": "bins="}
# study -> (section title, the axes its table rows are indexed by; any other axis that varies is appended)
STUDIES = {
    "lead": ("lead: the expert aims where the target will be (velocity) or where it is (none); linear target, 1 Hz, 200 ms",
             ("lead", "speed_m_s")),
    "families": ("families: target motions that change after the shot (200 ms; an expert source leads with velocity)",
                 ("target", "replan_hz")),
    "replan": ("replan: replan frequency (linear target, 0.3 m/s, 200 ms, lead velocity)", ("replan_hz",)),
    "rtc_grid": ("rtc_grid: inference delay d x execution horizon s (reversal target, 0.2 m/s, lead velocity)",
                 ("d_steps", "s_steps")),
    "speed": ("speed: target speed (1 Hz)", ("speed_m_s",)),
    "latency": ("latency (1 Hz)", ("latency_ms",)),
    "bins": ("bins: quantization (static target)", ("bins",)),
    "jump": ("jump: the target teleports mid-chunk", ("replan_hz",)),
    "perception": ("perception: oracle vs camera target channel", ("perception",)),
    "pick": ("pick: grasp the instructed cube on the conveyor and lift it (1 Hz, 200 ms, expert lead velocity)",
             ("target", "speed_m_s")),
    "insert": ("insert: bins x clearance x sensing noise x compliance (static fixture, 1 Hz, 200 ms)",
               ("clearance_mm", "noise_m", "bins", "compliance")),
}


# ---- rows ----------------------------------------------------------------------------------


def _axis_value(v):
    if isinstance(v, str):  # rows read back from results.csv
        t = v.strip()
        if t in ("", "None", "nan", "NaN"):
            return None
        try:
            f = float(t)
        except ValueError:
            return t
        return int(f) if f.is_integer() and t.lstrip("+-").isdigit() else f
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return None
    if isinstance(v, np.generic):
        v = v.item()
    return v


def _flag(v) -> bool | None:
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, float, np.number)) and not (isinstance(v, float) and math.isnan(v)):
        return bool(v)
    if isinstance(v, str) and v.strip().lower() in ("true", "false", "1", "0"):
        return v.strip().lower() in ("true", "1")
    return None


def normalize(row: dict) -> dict:
    """A copy of ``row`` with every axis present (None where missing) and ``success`` a bool or None."""
    out = dict(row)
    out["study"] = str(row.get("study") or "sweep")
    out["mode"] = str(row.get("mode") or "?")
    for k in COND_AXES:
        out[k] = _axis_value(row.get(k))
    out["source"] = out["source"] or "expert"
    out["seed"] = _axis_value(row.get("seed"))
    out["success"] = _flag(row.get("success"))
    return out


def num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def sort_key(axis: str):
    order = ORDERS.get(axis, ())

    def key(v):
        if v is None:
            return (3, 0, "")
        if v in order:
            return (0, order.index(v), "")
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return (1, float(v), "")
        return (2, 0, str(v))

    return key


def ordered(axis: str, values) -> list:
    return sorted(set(values), key=sort_key(axis))


def fmt_value(axis: str, v) -> str:
    if v is None:
        return "-"
    if axis == "bins" and v == 0:
        return "none"
    return f"{v:g}" if isinstance(v, float) else str(v)


def cond_label(cond: dict, axes) -> str:
    parts = []
    for a in axes:
        v = cond.get(a)
        if a == "lead" and v in (None, "-"):
            continue
        parts.append(f"{PREFIX.get(a, '')}{fmt_value(a, v)}{UNIT.get(a, '') if v is not None else ''}")
    return ", ".join(parts) or "-"


def study_names(rows: list[dict]) -> list[str]:
    present = {r["study"] for r in rows}
    return [s for s in STUDIES if s in present] + sorted(present - set(STUDIES))


def row_axes(rows: list[dict], study: str, include_source: bool = False) -> list[str]:
    """The study's own axes, then every other condition axis that varies among its rows."""
    own = list(STUDIES.get(study, ("", ("target",)))[1])
    extra = [a for a in COND_AXES if a not in own and (include_source or a != "source")
             and len({r[a] for r in rows if r[a] is not None}) > 1]
    return (["source"] if "source" in extra else []) + own + [a for a in extra if a != "source"]


def success_stats(rs: list[dict]) -> tuple[int, int, float, float]:
    """(successes, n, Wilson lo, Wilson hi) over the rows with a known outcome."""
    known = [r["success"] for r in rs if r["success"] is not None]
    k, n = sum(known), len(known)
    return (k, n, *wilson_interval(k, n))


def mean_metric(rs: list[dict], key: str) -> float:
    v = [num(r.get(key)) for r in rs]
    v = [x for x in v if math.isfinite(x)]
    return float(np.mean(v)) if v else float("nan")


def fmt_cell(rs: list[dict]) -> str:
    """``success% [lo–hi] / final error mm`` (95 % Wilson interval, mean final error)."""
    k, n, lo, hi = success_stats(rs)
    if not n:
        return "-"
    err = mean_metric(rs, "final_error_m")
    e = f"{1000 * err:.0f} mm" if math.isfinite(err) else "- mm"
    return f"{100 * k / n:.0f}% [{100 * lo:.0f}–{100 * hi:.0f}] / {e}"


def modes_of(rows: list[dict]) -> list[str]:
    return ordered("mode", (r["mode"] for r in rows))


def _n_caption(ns: list[int]) -> str:
    ns = [n for n in ns if n]
    if not ns:
        return "n = 0"
    lo, hi = min(ns), max(ns)
    return f"n = {lo} episodes (seeds) per cell" if lo == hi else f"n = {lo} to {hi} episodes (seeds) per cell"


def study_tables(rows: list[dict], study: str) -> list[str]:
    """Markdown: one table per source, rows = the study's axes, columns = modes."""
    rs = [r for r in rows if r["study"] == study]
    sources = ordered("source", (r["source"] for r in rs))
    out = []
    for src in sources:
        sub = [r for r in rs if r["source"] == src]
        axes = row_axes(sub, study)
        modes = modes_of(sub)
        cells = defaultdict(list)
        for r in sub:
            cells[(tuple(r[a] for a in axes), r["mode"])].append(r)
        keys = sorted({k for k, _ in cells}, key=lambda t: tuple(sort_key(a)(v) for a, v in zip(axes, t)))
        ns = [success_stats(v)[1] for v in cells.values()]
        title = f"source **{src}**, " if len(sources) > 1 or src != "expert" else ""
        out += [f"{title}{_n_caption(ns)}; cell: success [95 % Wilson interval] / mean final error.", "",
                "| " + " | ".join(HEAD.get(a, a) for a in axes) + " | " + " | ".join(modes) + " |",
                "|---" * (len(axes) + len(modes)) + "|"]
        for key in keys:
            vals = [fmt_value(a, v) for a, v in zip(axes, key)]
            out.append("| " + " | ".join(vals + [fmt_cell(cells.get((key, m), [])) for m in modes]) + " |")
        out.append("")
    return out


# ---- paired comparisons --------------------------------------------------------------------


def conditions(rows: list[dict]) -> dict[tuple, dict[str, list[dict]]]:
    """(study, condition axes...) -> mode -> rows."""
    out: dict[tuple, dict[str, list[dict]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        out[(r["study"], *(r[a] for a in COND_AXES))][r["mode"]].append(r)
    return out


def best_mode(by_mode: dict[str, list[dict]], candidates: list[str]) -> str:
    """Highest success rate; ties -> lower mean final error; then the mode order."""
    def key(m):
        k, n, _, _ = success_stats(by_mode[m])
        err = mean_metric(by_mode[m], "final_error_m")
        return (-(k / n) if n else 1.0, err if math.isfinite(err) else math.inf, sort_key("mode")(m))

    return min(candidates, key=key)


def _verdict(pb: dict, pe: dict, a: str, b_word: str) -> tuple[str, str]:
    """Primary: success (McNemar); if not significant, final error (Wilcoxon; lower is better)."""
    if pb["p_mcnemar"] < ALPHA and pb["diff"] != 0:
        return (f"{a} better" if pb["diff"] > 0 else f"{b_word} better"), "success"
    p = pe["p_wilcoxon"]
    if math.isfinite(p) and p < ALPHA and pe["rank_balance"] != 0:
        return (f"{a} better" if pe["rank_balance"] < 0 else f"{b_word} better"), "final error"
    return "no significant difference (p >= 0.05)", "-"


def compare(rows: list[dict], a: str = "hybrid", b: str | None = None, study: str | None = None,
            where=None, candidates: tuple[str, ...] | None = None) -> list[dict]:
    """Paired comparisons of mode ``a`` against mode ``b`` (None: the best other mode of each
    condition, among ``candidates`` if given), per condition (same study and every condition axis), matched
    by seed. Differences are a minus b."""
    out = []
    for ckey, by_mode in conditions(rows).items():
        if (study is not None and ckey[0] != study) or a not in by_mode:
            continue
        cond = dict(zip(COND_AXES, ckey[1:]), study=ckey[0])
        if where is not None and not where(cond):
            continue
        others = ([m for m in by_mode if m != a and (candidates is None or m in candidates)] if b is None
                  else [m for m in (b,) if m in by_mode])
        if not others:
            continue
        other = best_mode(by_mode, others)
        ra = {r["seed"]: r for r in by_mode[a]}
        rb = {r["seed"]: r for r in by_mode[other]}
        seeds = sorted(set(ra) & set(rb), key=str)
        if not seeds:
            continue
        ok = [s for s in seeds if ra[s]["success"] is not None and rb[s]["success"] is not None]
        pb = paired_binary([ra[s]["success"] for s in ok], [rb[s]["success"] for s in ok])
        pe = paired_continuous([num(ra[s].get("final_error_m")) for s in seeds],
                               [num(rb[s].get("final_error_m")) for s in seeds])
        pr = paired_continuous([num(ra[s].get("reaction_s")) for s in seeds],
                               [num(rb[s].get("reaction_s")) for s in seeds])
        verdict, basis = _verdict(pb, pe, a, "other" if b is None else other)
        out.append(dict(cond=cond, a=a, b=other, n=len(seeds), binary=pb, error=pe, reaction=pr, verdict=verdict,
                        basis=basis))
    key_fns = {ax: sort_key(ax) for ax in COND_AXES}
    out.sort(key=lambda c: (c["cond"]["study"], *(key_fns[ax](c["cond"][ax]) for ax in COND_AXES)))
    return out


def _p(p: float) -> str:
    if not math.isfinite(p):
        return "–"
    return "<0.001" if p < 0.001 else f"{p:.3f}"


def _diff(d: float, lo: float, hi: float, scale: float, unit: str, digits: int) -> str:
    if not math.isfinite(d):
        return "–"
    f = f"{{:+.{digits}f}}"
    ci = f" [{f.format(scale * lo)}, {f.format(scale * hi)}]" if math.isfinite(lo) else ""
    return f"{f.format(scale * d)}{unit}{ci}"


def comparison_table(comps: list[dict], axes, brief: bool = False) -> list[str]:
    """Markdown table of :func:`compare`'s results; the condition is labelled by ``axes`` (a list,
    or a function of the condition giving one)."""
    if not comps:
        return []
    a = comps[0]["a"]
    if brief:
        lines = [f"| study | condition | best other | n | {a} / other success | verdict |", "|---" * 6 + "|"]
    else:
        lines = [f"| condition | other | n | {a} / other success | Δsuccess [95 % CI] | McNemar p | "
                 "Δfinal error [95 % CI] | Wilcoxon p | Δreaction [95 % CI] | verdict |", "|---" * 10 + "|"]
    for c in comps:
        pb, pe, pr = c["binary"], c["error"], c["reaction"]
        succ = f"{pb['successes_a']}/{pb['n']} vs {pb['successes_b']}/{pb['n']}"
        label = cond_label(c["cond"], axes(c["cond"]) if callable(axes) else axes)
        if brief:
            lines.append(f"| {c['cond']['study']} | {label} | {c['b']} | {c['n']} | {succ} | {c['verdict']} |")
            continue
        cells = [label, c["b"], str(c["n"]), succ, _diff(pb["diff"], pb["diff_lo"], pb["diff_hi"], 100, " pp", 0),
                 _p(pb["p_mcnemar"]), _diff(pe["mean_diff"], pe["diff_lo"], pe["diff_hi"], 1000, " mm", 0),
                 _p(pe["p_wilcoxon"]),
                 _diff(pr["mean_diff"], pr["diff_lo"], pr["diff_hi"], 1, " s", 2)
                 + (f" (n={pr['n']})" if pr["n"] else ""),
                 c["verdict"] + (f" ({c['basis']})" if c["basis"] != "-" else "")]
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def group_of(cond: dict) -> tuple:
    """(source, lead) group of a condition, for the 'where it adds nothing' tables."""
    lead = cond.get("lead")
    return cond["source"], (None if lead in (None, "-") else lead)


def group_label(group: tuple) -> str:
    src, lead = group
    return src if lead is None else f"{src}, lead {lead}"
