"""The torque figure of the fault suite: one episode (:data:`~scenarios.faults.settings.PLOT_CELL`, the first
seed) re-run with its log kept, and its commanded torque and torque rate around the onset (``fault_torque.png``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenarios.faults.cells import run_cell
from scenarios.faults.injectors import FaultSpec
from scenarios.faults.settings import PLOT_CELL

#: the figure's file name in the output directory.
PLOT_NAME = "fault_torque.png"


@dataclass(frozen=True)
class PlotEpisode:
    """The episode of the torque figure: its cell, where the figure is, and whether it was drawn (``note`` says
    why not: the episode raised)."""

    fault: str
    mode: str
    source: str
    seed: int
    path: Path
    drawn: bool
    note: str = ""


def run_plot_episode(args, out: Path) -> PlotEpisode:
    """Re-runs the plot episode here (deterministic), whatever the selection, and draws its figure into ``out``."""
    plot_fault, plot_mode, plot_source = PLOT_CELL
    plot_cell = dict(fault=plot_fault, mode=plot_mode, source=plot_source, seed=args.seed, target=args.target,
                     speed=args.speed, duration_s=args.duration_s, onset_s=args.onset_s,
                     **({"task": args.task} if getattr(args, "task", "reach") != "reach" else {}))
    plot_row, plot_log = run_cell(plot_cell, keep_log=True)
    plot_path = out / PLOT_NAME
    if plot_log is None:
        return PlotEpisode(plot_fault, plot_mode, plot_source, args.seed, plot_path, drawn=False,
                           note=f"(the plot episode raised: {plot_row['raised']})")
    plot_fault_torque(plot_log, FaultSpec(plot_fault, t_fault_s=args.onset_s), plot_path,
                      f"{plot_fault}, {plot_mode}, {plot_source} source, seed {args.seed}: commanded torque and "
                      f"torque rate around the onset ({args.onset_s:g} s)")
    return PlotEpisode(plot_fault, plot_mode, plot_source, args.seed, plot_path, drawn=True)


def plot_fault_torque(log, spec: FaultSpec, path: Path, title: str, window_s: float = 0.5) -> None:
    """Commanded torque of the 7 joints and |dtau/dt| with the 1000 N m/s line, +-``window_s`` around the onset."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from controllers.safety import CommandLimits

    t, tau = log.t_s, log.tau_cmd_nm
    dt = float(t[1] - t[0])
    rate = np.vstack([np.zeros((1, 7)), np.abs(np.diff(tau, axis=0)) / dt])
    t0 = spec.t_fault_s
    sel = (t >= t0 - window_s) & (t <= t0 + window_s)
    start, end = spec.window_s(dt)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    for j in range(7):
        ax1.plot(t[sel], tau[sel, j], lw=1.0, label=f"joint {j + 1}")
        ax2.plot(t[sel], rate[sel, j], lw=1.0)
    for ax in (ax1, ax2):
        ax.axvspan(start, min(end, t0 + window_s), color="tab:red", alpha=0.12, label="fault window" if ax is ax1 else None)
    ax2.axhline(CommandLimits().dtau_max_nm_s, color="k", ls="--", lw=1.0, label="1000 N m/s")
    ax1.set_ylabel("commanded torque (N m)")
    ax2.set_ylabel("|dtau/dt| (N m/s)")
    ax2.set_xlabel("time (s)")
    ax1.legend(ncol=4, fontsize=7, loc="upper left")
    ax2.legend(fontsize=7, loc="upper left")
    ax1.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
