"""``report.md`` and its figures from the sweep's rows (one row per episode).

Per study a success table (95 % Wilson intervals), then paired same-seed comparisons of hybrid
against the best other mode of each condition (McNemar / Wilcoxon), and the conditions where the
control layer adds nothing. Tables: :mod:`scenarios.sweep.tables`; figures:
:mod:`scenarios.sweep.figures`; statistics: :mod:`scenarios.stats`.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from scenarios.sweep import figures as figs
from mmact_ctrl.stats import wilson_interval
from scenarios.sweep.tables import (STUDIES, compare, comparison_table, cond_label, group_label, group_of, modes_of,
                                    normalize, num, ordered, row_axes, sort_key, study_names,
                                    study_tables)

HOW_TO_READ = (
    "**How to read this.** A cell is the success rate over episodes (one per seed) with its 95 % Wilson score "
    "interval in brackets, then the mean final TCP-target error. Comparisons are *paired*: two modes of the same "
    "condition (study, source, lead, target, speed, replan rate, latency, d, s, bins, perception) run the same "
    "seeds, and only seeds both ran are used. Δ is hybrid minus the other mode: Δsuccess in percentage points "
    "with Newcombe's paired score interval and the exact McNemar test (binomial test on the discordant seeds); "
    "Δfinal error and Δreaction time are mean paired differences with a 95 % t-interval, tested with the "
    "Wilcoxon signed-rank test (pairs with a NaN dropped). The verdict rests on success first and, when that is "
    "not significant, on final error; significance is p < 0.05, two-sided. The comparisons are many and "
    "**not corrected for multiple comparisons**, so about 1 in 20 true null effects will read as significant; "
    "the best other mode is also picked on the same episodes, which favours it. With few seeds nothing can be "
    "significant: McNemar needs at least 6 discordant seeds all one way, Wilcoxon at least 6 pairs."
)


def _header(rows: list[dict], wall_s: float, resumed: int) -> list[str]:
    src = Counter(r["source"] for r in rows)
    srcs = ", ".join(f"{s} ({src[s]} episodes)" for s in ordered("source", src)) or "none"
    studies = ", ".join(f"`{s}`" for s in study_names(rows)) or "none"
    return ["# Sweep report", "",
            f"{len(rows)} episodes ({resumed} resumed from earlier runs); this run took {wall_s:.0f} s. "
            f"Sources: {srcs}. Studies: {studies}. Raw rows: `results.csv`.", "", HOW_TO_READ, ""]


def _jump_lines(rows: list[dict]) -> list[str]:
    out = []
    for g in sorted({group_of(r) for r in rows}, key=str):
        for m in modes_of([r for r in rows if group_of(r) == g]):
            rs = [r for r in rows if group_of(r) == g and r["mode"] == m]
            n = int(sum(num(r.get("n_jumps")) for r in rs if num(r.get("n_jumps")) >= 0))
            rec = int(sum(num(r.get("jumps_recovered")) for r in rs if num(r.get("jumps_recovered")) >= 0))
            if n and rec <= n:
                lo, hi = wilson_interval(rec, n)
                med = sorted(x for x in (num(r.get("jump_recovery_s")) for r in rs) if x == x)
                out.append(f"- {group_label(g)}, {m}: {rec}/{n} jumps recovered within 1 s ({100 * rec / n:.0f}% "
                           f"[{100 * lo:.0f}–{100 * hi:.0f}], jumps pooled over episodes); median recovery "
                           + (f"{med[len(med) // 2]:.2f} s" if med else "n/a"))
    return out + [""] if out else []


def _study_section(rows: list[dict], study: str, out: Path) -> list[str]:
    title = STUDIES.get(study, (f"{study} (mode x target)",))[0]
    parts = [f"## {title}", "", *study_tables(rows, study)]
    fig = {"replan": ("replan_hz", "replan frequency [Hz]", True), "speed": ("speed_m_s", "target speed [m/s]", False),
           "latency": ("latency_ms", "latency [ms]", False)}.get(study)
    if fig and figs.success_vs_axis(rows, study, fig[0], out / f"{study}.png", fig[1], logx=fig[2]):
        parts += [f"![{study}]({study}.png)", ""]
    if study == "replan":
        vals = figs.chunk_jumps(rows, out / "chunk_jumps.png")
        if vals:
            parts += ["Chunk-boundary jumps (largest TCP acceleration near a chunk switch, mean [95 % t-interval]):",
                      "", "| mode | m/s^2 |", "|---|---|"]
            parts += [f"| {m} | {v[0]:.2f} [{v[1]:.2f}, {v[2]:.2f}] |" for m, v in vals.items()]
            parts += ["", "![chunk jumps](chunk_jumps.png)", ""]
    if study == "rtc_grid" and figs.rtc_heatmap(rows, out / "rtc_grid.png"):
        parts += [f"d: nominal inference delay, s: execution horizon, both in chunk steps of 0.1 s; cells marked × "
                  f"have d >= the chunk horizon ({figs.CHUNK_HORIZON}).", "", "![rtc grid](rtc_grid.png)", ""]
    if study == "families" and figs.reaction_bars(rows, out / "reaction.png"):
        parts += ["Reaction time per target family (mean and 95 % t-interval over the episodes where a reaction was "
                  "measured; episodes without one are left out).", "", "![reaction](reaction.png)", ""]
    if study == "bins" and figs.bins_plot(rows, out / "bins.png"):
        parts += ["Final error vs number of action bins (none = no quantization), beside the half-bin error, the "
                  "control floor (the same mode without quantization) and the perception noise.", "",
                  "![bins](bins.png)", ""]
    if study == "jump":
        parts += _jump_lines([r for r in rows if r["study"] == "jump"])
    return parts


def _paired_section(rows: list[dict]) -> tuple[list[str], list[dict]]:
    parts, all_comps = ["## Paired comparisons: hybrid vs the best other mode", ""], []
    for study in study_names(rows):
        comps = compare(rows, "hybrid", None, study=study)
        if comps:
            all_comps += comps
            axes = row_axes([r for r in rows if r["study"] == study], study, include_source=True)
            parts += [f"### {study}", "", *comparison_table(comps, axes)]
    chunk_only = tuple(m for m in modes_of(rows) if m not in ("hybrid", "residual"))
    for study in ("lead", "families"):
        comps = compare(rows, "hybrid", None, study=study, candidates=chunk_only)
        if comps:
            axes = row_axes([r for r in rows if r["study"] == study], study, include_source=True)
            parts += [f"### {study}: hybrid vs the best chunk-only baseline ({', '.join(chunk_only)}: the methods "
                      "that do not read the measurement channel)", "", *comparison_table(comps, axes)]
    res = compare(rows, "residual", "open_loop", study="families", where=lambda c: num(c["replan_hz"]) == 1.0)
    if res:
        axes = row_axes([r for r in rows if r["study"] == "families"], "families", include_source=True)
        parts += ["### residual vs open_loop (families, 1 Hz)", "", *comparison_table(res, axes)]
    if not all_comps and not res:
        parts += ["No condition has hybrid (or residual and open_loop) on common seeds.", ""]
    return parts, all_comps


def _nothing_section(rows: list[dict], comps: list[dict]) -> list[str]:
    if not comps:
        return []
    parts = ["## Where the control layer adds nothing", "",
             "Conditions where hybrid is *not* significantly better than the best baseline (p >= 0.05, or the "
             "baseline is better), per chunk source.", ""]
    axes_of = {s: [a for a in row_axes([r for r in rows if r["study"] == s], s) if a not in ("source", "lead")]
               for s in study_names(rows)}

    def where(c):
        return f"{c['cond']['study']}: {cond_label(c['cond'], axes_of[c['cond']['study']])}"

    for g in sorted({group_of(c["cond"]) for c in comps}, key=lambda g: (sort_key("source")(g[0]),
                                                                          sort_key("lead")(g[1]))):
        cs = [c for c in comps if group_of(c["cond"]) == g]
        nothing = [c for c in cs if c["verdict"] != "hybrid better"]
        worse = [c for c in nothing if c["verdict"] == "other better"]
        label = group_label(g)

        parts.append(f"### {label}")
        parts.append("")
        if not nothing:
            parts += [f"{label}: hybrid is significantly better than the best baseline in all {len(cs)} compared "
                      "conditions.", ""]
            continue
        txt = (f"{label}: hybrid is significantly better than the best baseline in {len(cs) - len(nothing)} of "
               f"{len(cs)} compared conditions; it adds nothing significant in {len(nothing)}: "
               + "; ".join(where(c) for c in nothing) + ".")
        weak = [c for c in nothing if c["n"] < 6]
        if weak:
            txt += (f" {len(weak)} of these have fewer than 6 paired seeds, where neither test can reach p < 0.05 "
                    "whatever the effect: they need more seeds, not a conclusion.")
        if worse:
            txt += f" In {len(worse)} of these the baseline is significantly better: " + "; ".join(
                f"{where(c)} ({c['b']})" for c in worse) + "."
        parts += [txt, "", *comparison_table(nothing, lambda cond: axes_of[cond["study"]], brief=True)]
    return parts


def write_report(rows: list[dict], out: Path, wall_s: float, resumed: int = 0, notes: list[str] | None = None) -> None:
    """Write ``out/report.md`` and the PNGs it links; ``notes`` are printed under the header (e.g. modes the source
    could not run)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = [normalize(r) for r in rows]
    parts = _header(rows, wall_s, resumed)
    if notes:
        parts += [f"- {n}" for n in notes] + [""]
    for study in study_names(rows):
        parts += _study_section(rows, study, out)
    paired, comps = _paired_section(rows)
    parts += paired + _nothing_section(rows, comps)
    (out / "report.md").write_text("\n".join(parts))
