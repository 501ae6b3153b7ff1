"""``report.md`` and its figures from the sweep's rows (one row per episode)."""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from policy.action_tokenizer import ActionBounds  # noqa: E402

MODE_ORDER = ("open_loop", "receding", "temporal_ensemble", "inpaint", "hybrid")


def _finite(values) -> list[float]:
    return [float(v) for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))]


def _group(rows: list[dict], study: str, axis: str) -> dict[str, dict[float, list[dict]]]:
    """mode -> axis value -> rows."""
    out: dict[str, dict[float, list[dict]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        if r["study"] == study:
            out[r["mode"]][r[axis]].append(r)
    return out


def _modes(groups) -> list[str]:
    return [m for m in MODE_ORDER if m in groups] + [m for m in groups if m not in MODE_ORDER]


def _mean(rs: list[dict], key: str) -> float:
    v = _finite(r[key] for r in rs)
    return float(np.mean(v)) if v else float("nan")


def _pivot_table(groups, axis_label: str, fmt_axis=lambda x: f"{x:g}") -> str:
    modes = _modes(groups)
    values = sorted({v for m in modes for v in groups[m]})
    head = f"| {axis_label} | " + " | ".join(modes) + " |"
    sep = "|---" * (len(modes) + 1) + "|"
    lines = [head, sep]
    for v in values:
        cells = []
        for m in modes:
            rs = groups[m].get(v, [])
            if not rs:
                cells.append("-")
                continue
            cells.append(f"{100 * _mean(rs, 'success'):.0f}% / {1000 * _mean(rs, 'final_error_m'):.0f} mm")
        lines.append(f"| {fmt_axis(v)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _line_plot(groups, axis: str, path: Path, xlabel: str, logx: bool = False) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for m in _modes(groups):
        xs = sorted(groups[m])
        axes[0].plot(xs, [100 * _mean(groups[m][x], "success") for x in xs], marker="o", label=m)
        axes[1].plot(xs, [1000 * _mean(groups[m][x], "mean_error_m") for x in xs], marker="o", label=m)
    axes[0].set_ylabel("success rate [%]")
    axes[1].set_ylabel("mean TCP-target error [mm]")
    axes[1].set_yscale("log")
    for ax in axes:
        ax.set_xlabel(xlabel)
        if logx:
            ax.set_xscale("log")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _bins_plot(groups, path: Path, noise_m: float = 0.002) -> None:
    bounds = ActionBounds()
    span = max(h - lo for h, lo in zip(bounds.high[:3], bounds.low[:3]))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    unq = {}
    for m in _modes(groups):
        xs = sorted(b for b in groups[m] if b > 0)
        ax.plot(xs, [1000 * _mean(groups[m][b], "final_error_m") for b in xs], marker="o", label=f"{m}: final error")
        if 0 in groups[m]:
            unq[m] = 1000 * _mean(groups[m][0], "final_error_m")
    grid = np.logspace(np.log10(32), np.log10(16384), 50)
    ax.plot(grid, 1000 * span / (2 * grid), "k--", lw=1, label="half a bin (largest position range)")
    for m, v in unq.items():
        ax.axhline(v, ls=":", lw=1.2, color="tab:gray" if m == "open_loop" else "tab:green",
                   label=f"{m}, no quantization (control floor)")
    ax.axhline(1000 * noise_m, color="tab:red", ls="-.", lw=1, label=f"perception noise std ({1000 * noise_m:g} mm)")
    ax.axvline(2048, color="0.7", lw=0.8)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("action bins per dimension")
    ax.set_ylabel("final TCP-target error [mm], static target")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _jumps_plot(rows: list[dict], path: Path) -> dict[str, float]:
    per_mode = defaultdict(list)
    for r in rows:
        if r["study"] == "replan":
            per_mode[r["mode"]].append(r["chunk_jump_acc_m_s2"])
    modes = _modes(per_mode)
    vals = {m: float(np.mean(per_mode[m])) for m in modes}
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.bar(modes, [vals[m] for m in modes], color="tab:blue")
    ax.set_ylabel("largest TCP acceleration\nnear a chunk switch [m/s^2]")
    ax.set_title("chunk-boundary jumps (replan study, mean over cells)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return vals


def _claims(rows: list[dict]) -> list[str]:
    out = []
    rep = _group(rows, "replan", "replan_hz")
    if "hybrid" in rep and "open_loop" in rep and 1.0 in rep["hybrid"]:
        h1 = _mean(rep["hybrid"][1.0], "success")
        top = max(rep["open_loop"])
        o10 = _mean(rep["open_loop"][top], "success")
        verdict = "holds" if h1 >= o10 else "DOES NOT HOLD"
        out.append(f"- hybrid at 1 Hz: {100 * h1:.0f}% success; open_loop at {top:g} Hz: {100 * o10:.0f}% -> the claim "
                   f"'hybrid at 1 Hz >= open_loop at {top:g} Hz' {verdict}.")
    if "hybrid" in rep:
        for f in sorted(x for x in rep["hybrid"] if x <= 2.0):
            h = _mean(rep["hybrid"][f], "success")
            he = _mean(rep["hybrid"][f], "mean_error_m")
            for m in ("temporal_ensemble", "receding", "inpaint"):
                if m in rep and f in rep[m]:
                    b, be = _mean(rep[m][f], "success"), _mean(rep[m][f], "mean_error_m")
                    better = h > b or (h == b and he < be)
                    word = "beats" if better else "does NOT beat"
                    out.append(f"- {f:g} Hz: hybrid {100 * h:.0f}% ({1000 * he:.0f} mm mean error) {word} {m} "
                               f"{100 * b:.0f}% ({1000 * be:.0f} mm)")
    jump = _group(rows, "jump", "replan_hz")
    for m in _modes(jump):
        rs = [r for v in jump[m].values() for r in v]
        n = sum(r["n_jumps"] for r in rs)
        rec = sum(r["jumps_recovered"] for r in rs)
        med = _finite(r["jump_recovery_s"] for r in rs)
        if n:
            out.append(f"- jump target, {m}: {rec}/{n} jumps ({100 * rec / n:.0f}%) recovered within 1 s, "
                       f"median recovery {np.median(med) if med else float('nan'):.2f} s")
    return out


def write_report(rows: list[dict], out: Path, wall_s: float, resumed: int = 0) -> None:
    """Write ``out/report.md`` and the PNGs it links."""
    parts = ["# Sweep report", "",
             f"{len(rows)} episodes ({resumed} resumed from earlier runs); this run took {wall_s:.0f} s. "
             "Cells: success rate / mean final error over seeds. Raw rows: `results.csv`.", ""]
    claims = _claims(rows)
    if claims:
        parts += ["## What the numbers say", "", *claims, ""]
    studies = [("replan", "replan_hz", "replan frequency [Hz]", True), ("speed", "speed_m_s", "target speed [m/s]", False),
               ("latency", "latency_ms", "latency [ms]", False)]
    for study, axis, label, logx in studies:
        g = _group(rows, study, axis)
        if not g:
            continue
        png = f"{study}.png"
        _line_plot(g, axis, out / png, label, logx=logx)
        parts += [f"## {study}", "", _pivot_table(g, label), "", f"![{study}]({png})", ""]
    g = _group(rows, "bins", "bins")
    if g:
        _bins_plot(g, out / "bins.png")
        parts += ["## quantization (static target)", "",
                  "Final error vs number of action bins (0 = no quantization), beside the half-bin error, the "
                  "control floor (the same mode without quantization) and the perception noise.", "",
                  _pivot_table(g, "bins", lambda b: "none" if b == 0 else f"{b:g}"), "", "![bins](bins.png)", ""]
    if any(r["study"] == "replan" for r in rows):
        vals = _jumps_plot(rows, out / "chunk_jumps.png")
        parts += ["## chunk-boundary jumps", "", "| mode | largest TCP acceleration near a switch [m/s^2] |", "|---|---|"]
        parts += [f"| {m} | {v:.2f} |" for m, v in vals.items()]
        parts += ["", "![chunk jumps](chunk_jumps.png)", ""]
    g = _group(rows, "jump", "replan_hz")
    if g:
        parts += ["## jump target", "", _pivot_table(g, "replan frequency [Hz]"), ""]
    g = _group(rows, "perception", "perception")
    if g:
        parts += ["## perception (linear target, 0.2 m/s, 1 Hz)", "",
                  "The hybrid layer's target channel: the oracle (truth + 2 mm noise, 100 Hz) vs the camera (the ball "
                  "measured in rendered depth + segmentation frames, 30 Hz, 50 ms latency, occlusion).", "",
                  _pivot_table(g, "perception", str), ""]
    (out / "report.md").write_text("\n".join(parts))
