"""Plots a user reads: TCP vs target over time, and the error curve."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mmact_ctrl.loop import EpisodeLog  # noqa: E402


def plot_runs(logs: dict[str, EpisodeLog], path: str | Path, success_radius_m: float = 0.03, title: str = "") -> None:
    """One column per run: x/y/z of TCP (solid), target (dashed), reference (dotted); error below."""
    names = list(logs)
    fig, axes = plt.subplots(2, len(names), figsize=(6.0 * len(names), 7.0), sharex=True, squeeze=False)
    colors = ("tab:red", "tab:green", "tab:blue")
    for col, name in enumerate(names):
        log = logs[name]
        ax = axes[0, col]
        for i, axis in enumerate("xyz"):
            ax.plot(log.t_s, log.ee_pos_m[:, i], color=colors[i], lw=1.5, label=f"TCP {axis}")
            ax.plot(log.t_s, log.target_pos_m[:, i], color=colors[i], lw=1.0, ls="--", label=f"target {axis}")
            ax.plot(log.t_s, log.ref_pos_m[:, i], color=colors[i], lw=0.8, ls=":", alpha=0.7)
        for ts in log.chunk_active_s:
            ax.axvline(ts, color="0.8", lw=0.6, zorder=0)
        ax.set_title(f"{name} (seed {log.seed})")
        ax.set_ylabel("position [m]")
        if col == 0:
            ax.legend(ncol=3, fontsize=7, loc="best")
        err = np.linalg.norm(log.ee_pos_m - log.target_pos_m, axis=1)
        ax = axes[1, col]
        ax.plot(log.t_s, 1000.0 * err, color="k", lw=1.2)
        ax.axhline(1000.0 * success_radius_m, color="tab:orange", ls="--", lw=1.0, label="success radius")
        for ts in (tj for tj in log.jump_times_s if tj <= log.t_s[-1]):
            ax.axvline(ts, color="tab:purple", ls=":", lw=1.0)
        ax.set_yscale("log")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("TCP-target error [mm]")
        ax.legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
