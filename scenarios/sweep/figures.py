"""The sweep report's PNG figures (matplotlib, Agg). Each function takes normalized rows
(:func:`scenarios.sweep.tables.normalize`), writes one PNG and returns whether it wrote one."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mmact_ctrl.stats import t_interval  # noqa: E402
from scenarios.sweep.tables import (group_label, group_of, mean_metric, modes_of, num, ordered,  # noqa: E402
                                    success_stats)

CHUNK_HORIZON = 16  # waypoints per chunk (0.1 s each): d >= H means the next chunk is never on time


def _groups(rows: list[dict]) -> list[tuple]:
    gs = {group_of(r) for r in rows}
    return sorted(gs, key=lambda g: (ordered("source", [x[0] for x in gs]).index(g[0]),
                                     ordered("lead", [x[1] for x in gs]).index(g[1])))


def _save(fig, path: Path) -> bool:
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return True


def _yerr(centre: list[float], lo: list[float], hi: list[float]) -> np.ndarray:
    c, lo, hi = (np.asarray(x, dtype=float) for x in (centre, lo, hi))
    return np.nan_to_num(np.vstack([c - lo, hi - c]), nan=0.0)


def success_vs_axis(rows: list[dict], study: str, axis: str, path: Path, xlabel: str, logx: bool = False) -> bool:
    """Success rate (95 % Wilson bars) and mean error vs ``axis``, one line per mode, a row per group."""
    rs = [r for r in rows if r["study"] == study and r[axis] is not None]
    if not rs:
        return False
    groups, ticks = _groups(rs), ordered(axis, (r[axis] for r in rs))
    fig, axes = plt.subplots(len(groups), 2, figsize=(11, 3.8 * len(groups)), squeeze=False)
    for gi, g in enumerate(groups):
        sub = [r for r in rs if group_of(r) == g]
        modes = modes_of(sub)
        for mi, m in enumerate(modes):
            by_x = defaultdict(list)
            for r in sub:
                if r["mode"] == m:
                    by_x[r[axis]].append(r)
            xs = sorted(by_x)
            st = [success_stats(by_x[x]) for x in xs]
            p = [k / n if n else np.nan for k, n, _, _ in st]
            dodge = 1 + 0.025 * (mi - (len(modes) - 1) / 2)  # side by side, so the bars stay readable
            xd = [x * dodge for x in xs] if logx else [x + (dodge - 1) * (max(ticks) - min(ticks) or 1) for x in xs]
            axes[gi, 0].errorbar(xd, [100 * v for v in p], yerr=100 * _yerr(p, [s[2] for s in st], [s[3] for s in st]),
                                 marker="o", capsize=3, label=m)
            axes[gi, 1].plot(xs, [1000 * mean_metric(by_x[x], "mean_error_m") for x in xs], marker="o", label=m)
        axes[gi, 0].set_ylabel("success rate [%]\n(95 % Wilson)")
        axes[gi, 1].set_ylabel("mean TCP-target error [mm]")
        axes[gi, 1].set_yscale("log")
        for ax in axes[gi]:
            ax.set_title(group_label(g), fontsize=9)
            ax.set_xlabel(xlabel)
            if logx:
                ax.set_xscale("log")
                ax.minorticks_off()
            ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
            ax.grid(alpha=0.3)
        axes[gi, 1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1))
    return _save(fig, path)


def rtc_heatmap(rows: list[dict], path: Path, horizon: int = CHUNK_HORIZON) -> bool:
    """Success rate over d (rows) x s (columns), one subplot per mode, a row of subplots per group."""
    rs = [r for r in rows if r["study"] == "rtc_grid" and r["d_steps"] is not None and r["s_steps"] is not None]
    if not rs:
        return False
    groups, modes = _groups(rs), modes_of(rs)
    ds, ss = ordered("d_steps", (r["d_steps"] for r in rs)), ordered("s_steps", (r["s_steps"] for r in rs))
    fig, axes = plt.subplots(len(groups), len(modes), figsize=(2.2 + 0.55 * len(ss) * len(modes),
                                                               0.9 + 0.5 * len(ds) * len(groups)), squeeze=False)
    for gi, g in enumerate(groups):
        for mi, m in enumerate(modes):
            ax = axes[gi, mi]
            grid = np.full((len(ds), len(ss)), np.nan)
            for i, d in enumerate(ds):
                for j, s in enumerate(ss):
                    k, n, _, _ = success_stats([r for r in rs if group_of(r) == g and r["mode"] == m
                                                and r["d_steps"] == d and r["s_steps"] == s])
                    if n:
                        grid[i, j] = k / n
            ax.imshow(100 * grid, vmin=0, vmax=100, cmap="RdYlGn", aspect="auto", origin="lower")
            for i, d in enumerate(ds):
                for j, _ in enumerate(ss):
                    late = num(d) >= horizon
                    txt = "" if np.isnan(grid[i, j]) else f"{100 * grid[i, j]:.0f}"
                    ax.text(j, i, txt + ("\n×" if late else ""), ha="center", va="center", fontsize=7,
                            color="k", fontweight="bold" if late else "normal")
            ax.set_xticks(range(len(ss)), [str(s) for s in ss], fontsize=7)
            ax.set_yticks(range(len(ds)), [str(d) for d in ds], fontsize=7)
            ax.set_title(f"{m}\n{group_label(g)}", fontsize=8)
            ax.set_xlabel("s [chunk steps]", fontsize=7)
            if mi == 0:
                ax.set_ylabel("d [chunk steps]", fontsize=7)
    fig.suptitle(f"success rate [%] (× : d >= chunk horizon {horizon})", fontsize=9)
    return _save(fig, path)


def reaction_bars(rows: list[dict], path: Path) -> bool:
    """Mean reaction_s (95 % t-interval) per target family and mode; a subplot per group x replan_hz."""
    rs = [r for r in rows if r["study"] == "families" and np.isfinite(num(r.get("reaction_s")))]
    if not rs:
        return False
    groups, modes = _groups(rs), modes_of(rs)
    hzs, fams = ordered("replan_hz", (r["replan_hz"] for r in rs)), ordered("target", (r["target"] for r in rs))
    fig, axes = plt.subplots(len(groups), len(hzs), figsize=(1.2 + 0.5 * len(fams) * len(modes) * len(hzs) / 2,
                                                             3.6 * len(groups)), squeeze=False)
    width = 0.8 / max(1, len(modes))
    for gi, g in enumerate(groups):
        for hi, hz in enumerate(hzs):
            ax = axes[gi, hi]
            for mi, m in enumerate(modes):
                st = [t_interval([num(r.get("reaction_s")) for r in rs if group_of(r) == g and r["replan_hz"] == hz
                                  and r["mode"] == m and r["target"] == f]) for f in fams]
                xs = np.arange(len(fams)) + (mi - (len(modes) - 1) / 2) * width
                ax.bar(xs, [s[0] for s in st], width, yerr=_yerr(*zip(*st)) if st else None, capsize=2, label=m)
            ax.set_xticks(range(len(fams)), [str(f) for f in fams], fontsize=8)
            ax.set_ylabel("reaction time [s]")
            ax.set_title(f"{group_label(g)}, {hz:g} Hz" if hz is not None else group_label(g), fontsize=9)
            ax.grid(alpha=0.3, axis="y")
        axes[gi, -1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1))
    return _save(fig, path)


def chunk_jumps(rows: list[dict], path: Path) -> dict[str, tuple[float, float, float]]:
    """Largest TCP acceleration near a chunk switch per mode (replan study; mean, 95 % t-interval)."""
    per_mode = defaultdict(list)
    for r in rows:
        if r["study"] == "replan":
            per_mode[r["mode"]].append(num(r.get("chunk_jump_acc_m_s2")))
    vals = {m: t_interval(per_mode[m]) for m in modes_of([{"mode": m} for m in per_mode])}
    vals = {m: v for m, v in vals.items() if np.isfinite(v[0])}
    if not vals:
        return {}
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ms = list(vals)
    ax.bar(ms, [vals[m][0] for m in ms], yerr=_yerr(*zip(*vals.values())), capsize=3, color="tab:blue")
    ax.set_ylabel("largest TCP acceleration\nnear a chunk switch [m/s^2]")
    ax.set_title("chunk-boundary jumps (replan study, mean and 95 % t-interval over episodes)", fontsize=9)
    _save(fig, path)
    return vals


def bins_plot(rows: list[dict], path: Path, noise_m: float = 0.002) -> bool:
    """Final error vs action bins beside half a bin, the unquantized control floor and the noise."""
    from policy.action_tokenizer import ActionBounds

    rs = [r for r in rows if r["study"] == "bins" and r["bins"] is not None]
    if not rs:
        return False
    bounds = ActionBounds()
    span = max(h - lo for h, lo in zip(bounds.high[:3], bounds.low[:3]))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for m in modes_of(rs):
        by_b = defaultdict(list)
        for r in rs:
            if r["mode"] == m:
                by_b[r["bins"]].append(r)
        xs = sorted(b for b in by_b if num(b) > 0)
        st = [t_interval([num(r.get("final_error_m")) for r in by_b[b]]) for b in xs]
        if xs:
            ax.errorbar(xs, [1000 * s[0] for s in st], yerr=1000 * _yerr(*zip(*st)), marker="o", capsize=3,
                        label=f"{m}: final error")
        if 0 in by_b:
            ax.axhline(1000 * mean_metric(by_b[0], "final_error_m"), ls=":", lw=1.2,
                       color="tab:gray" if m == "open_loop" else "tab:green",
                       label=f"{m}, no quantization (control floor)")
    grid = np.logspace(np.log10(32), np.log10(16384), 50)
    ax.plot(grid, 1000 * span / (2 * grid), "k--", lw=1, label="half a bin (largest position range)")
    ax.axhline(1000 * noise_m, color="tab:red", ls="-.", lw=1, label=f"perception noise std ({1000 * noise_m:g} mm)")
    ax.axvline(2048, color="0.7", lw=0.8)
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("action bins per dimension")
    ax.set_ylabel("final TCP-target error [mm], static target")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    return _save(fig, path)
