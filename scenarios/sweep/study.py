"""The study: where does the control layer beat the best fixes the field uses, and where does it add nothing?

    python -m scenarios.sweep --out docs/sweep               # default grid, expert source, ~10 min on 2 cores
    python -m scenarios.sweep --quick --out out/quick        # < 2 min
    python -m scenarios.sweep --source policy --out ...      # the same grid with the learned policy
    python -m scenarios.sweep --backend ray --out ...        # spread the same grid over a Ray cluster

The grid is the union of studies, each a cartesian product over mode x replan_hz x latency_ms x target x speed_m_s x
bins x seed x perception x lead (the expert's: ``velocity`` aims where two frames say the target will be, ``none``
where one frame shows it) x (d, s) (RTC's grid: inference delay d and execution horizon s in chunk steps of
0.1 s; then latency = d steps, the replan period = s steps, and ``receding`` runs s waypoints per chunk):

- ``lead``:     every mode, lead velocity vs none, linear target at 0.2 / 0.3 / 0.4 m/s (1 Hz, 200 ms);
- ``families``: every mode on the motions that change after the shot (reversal, swerve, jump, random_walk,
                accelerating) at 1 and 5 Hz (200 ms, lead velocity): the archery question;
- ``replan``:   every mode vs replan frequency (linear 0.3 m/s, 200 ms, lead velocity);
- ``rtc_grid``: every mode on d x s, d beyond the chunk (16 steps) included (reversal 0.2 m/s, lead velocity);
- ``bins``:     the quantization trap, 64 to 8192 bins and none (static target, open_loop and hybrid);
- ``perception``: hybrid with the oracle target channel vs the camera (30 Hz, 50 ms; linear, 0.2 m/s, 1 Hz).

Every mode of a study runs on the same seeds and the same target motions, and is given the same information: the
same chunks (the same source and lead), and the residual and hybrid layers the same 100 Hz measurement channel.
One episode per cell; each result is a JSON file under ``OUT/cells/`` so an interrupted sweep resumes where it
stopped. ``OUT/results.csv`` has one row per episode (every grid axis and every episode metric); ``OUT/report.md``
holds the tables with 95 % Wilson intervals, the paired comparisons (same seeds: McNemar, Wilcoxon) and the
conditions where the control layer adds nothing, and links the PNG figures.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
from dataclasses import dataclass
from itertools import product

from mmact_ctrl.config import MODES

AXES: tuple[str, ...] = ("study", "mode", "replan_hz", "latency_ms", "target", "speed_m_s", "bins", "seed", "perception",
                         "lead", "d_steps", "s_steps")
#: the axes of a contact task's cells (``--task pick|insert``); reach's cells carry none of them (their keys, and the
#: published reach sweeps, are unchanged)
TASK_AXES: tuple[str, ...] = ("task", "clearance_mm", "noise_m", "compliance")
PERCEPTIONS: tuple[str, ...] = ("oracle", "camera")
LEADS: tuple[str, ...] = ("velocity", "none")
#: the expert's waypoint spacing: one RTC step, s
STEP_S = 0.1


@dataclass(frozen=True)
class Study:
    """One cartesian product of the grid. With ``d_steps`` and ``s_steps`` (RTC's grid) the latency is
    ``d * STEP_S`` and the replan period ``s * STEP_S`` (``latency_ms`` and ``replan_hz`` are then ignored)."""

    name: str
    modes: tuple[str, ...]
    replan_hz: tuple[float, ...]
    latency_ms: tuple[float, ...]
    target: tuple[str, ...]
    speed_m_s: tuple[float, ...]
    bins: tuple[int, ...]
    seeds: tuple[int, ...]
    perception: tuple[str, ...] = ("oracle",)
    lead: tuple[str, ...] = ("velocity",)
    d_steps: tuple[int, ...] = ()
    s_steps: tuple[int, ...] = ()
    task: str = "reach"
    clearance_mm: tuple[float, ...] = (1.0,)
    noise_m: tuple[float, ...] = (0.002,)
    compliance: tuple[bool, ...] = (False,)
    #: pick's ``--close-at-grasp`` (README, Contact, point 14) off and / or on; another task has no such switch
    close_at_grasp: tuple[bool, ...] = (False,)

    def __post_init__(self) -> None:
        from scenarios.world.tasks.registry import TASKS, task_by_name

        if self.task not in TASKS:
            raise ValueError(f"study {self.name!r}: unknown task {self.task!r}; expected one of {TASKS}")
        if not self.close_at_grasp or any(not isinstance(g, bool) for g in self.close_at_grasp):
            raise ValueError(f"study {self.name!r}: close_at_grasp must be a list of true / false, got "
                             f"{self.close_at_grasp}")
        if any(self.close_at_grasp) and getattr(task_by_name(self.task), "close_below_reading_m", None) is None:
            raise ValueError(f"study {self.name!r}: close_at_grasp is a switch of pick, not of task {self.task!r}")
        if any(not (c > 0 and math.isfinite(c)) for c in self.clearance_mm) or \
                any(not (n >= 0 and math.isfinite(n)) for n in self.noise_m):
            raise ValueError(f"study {self.name!r}: clearance_mm must be > 0 and noise_m >= 0, got "
                             f"{self.clearance_mm} and {self.noise_m}")
        bad = [m for m in self.modes if m not in MODES]
        if bad:
            raise ValueError(f"study {self.name!r}: unknown mode(s) {bad}; expected some of {MODES}")
        if any(not (f > 0 and math.isfinite(f)) for f in self.replan_hz):
            raise ValueError(f"study {self.name!r}: replan_hz must be > 0, got {self.replan_hz}")
        if any(not (x >= 0) for x in self.latency_ms):
            raise ValueError(f"study {self.name!r}: latency_ms must be >= 0, got {self.latency_ms}")
        if any(not (x >= 0) for x in self.speed_m_s):
            raise ValueError(f"study {self.name!r}: speed_m_s must be >= 0, got {self.speed_m_s}")
        if any(b < 0 or b == 1 for b in self.bins):
            raise ValueError(f"study {self.name!r}: bins must be 0 or >= 2, got {self.bins}")
        if not self.seeds:
            raise ValueError(f"study {self.name!r}: needs at least one seed")
        bad = [x for x in self.perception if x not in PERCEPTIONS]
        if bad or not self.perception:
            raise ValueError(f"study {self.name!r}: perception must be some of {PERCEPTIONS}, got {self.perception}")
        bad = [x for x in self.lead if x not in LEADS]
        if bad or not self.lead:
            raise ValueError(f"study {self.name!r}: lead must be some of {LEADS}, got {self.lead}")
        if bool(self.d_steps) != bool(self.s_steps):
            raise ValueError(f"study {self.name!r}: d_steps and s_steps go together, got {self.d_steps} and {self.s_steps}")
        if any(int(d) != d or d < 0 for d in self.d_steps) or any(int(x) != x or x < 1 for x in self.s_steps):
            raise ValueError(f"study {self.name!r}: d_steps must be ints >= 0 and s_steps ints >= 1, got "
                             f"{self.d_steps} and {self.s_steps}")

    def cells(self) -> list[dict]:
        base = dict(study=self.name)
        if self.d_steps:
            timing = [dict(latency_ms=round(1000.0 * d * STEP_S, 6), replan_hz=round(1.0 / (s * STEP_S), 6),
                           d_steps=int(d), s_steps=int(s)) for d, s in product(self.d_steps, self.s_steps)]
        else:
            timing = [dict(latency_ms=lat, replan_hz=f, d_steps=None, s_steps=None)
                      for f, lat in product(self.replan_hz, self.latency_ms)]
        contact = [{}] if self.task == "reach" else [
            dict(task=self.task, clearance_mm=c, noise_m=n, compliance=bool(k), close_at_grasp=bool(g))
            for c, n, k, g in product(self.clearance_mm, self.noise_m, self.compliance, self.close_at_grasp)]
        return [
            {**base, "mode": m, **tm, "target": tg, "speed_m_s": sp, "bins": b, "seed": sd, "perception": pc, "lead": ld,
             **ct}
            for m, tm, tg, sp, b, ct, sd, pc, ld in product(
                self.modes, timing, self.target, self.speed_m_s, self.bins, contact, self.seeds, self.perception,
                self.lead,
            )
        ]


#: the motions that change after the shot (the archery question)
FAMILIES: tuple[str, ...] = ("reversal", "swerve", "jump", "random_walk", "accelerating")


def default_grid(quick: bool = False, seeds: int = 10) -> list[Study]:
    """The default grid: ``seeds`` seeds per cell in the lead and families studies (a paired test on n seeds cannot
    reach p < 0.05 below 6), fewer on the wide d x s grid and the replan curve."""
    all_modes = MODES
    if quick:
        s = (0, 1)
        return [
            Study("lead", all_modes, (1.0,), (200.0,), ("linear",), (0.3,), (2048,), s, lead=LEADS),
            Study("families", all_modes, (1.0,), (200.0,), ("reversal", "jump"), (0.3,), (2048,), s),
            Study("rtc_grid", all_modes, (1.0,), (200.0,), ("reversal",), (0.2,), (2048,), (0,), d_steps=(1, 4),
                  s_steps=(2, 8)),
            Study("bins", ("open_loop",), (1.0,), (200.0,), ("static",), (0.0,), (64, 2048, 0), (0,)),
        ]
    s = tuple(range(seeds))
    few = tuple(range(max(1, min(seeds, 3))))
    return [
        Study("lead", all_modes, (1.0,), (200.0,), ("linear",), (0.2, 0.3, 0.4), (2048,), s, lead=LEADS),
        Study("families", all_modes, (1.0, 5.0), (200.0,), FAMILIES, (0.3,), (2048,), s),
        Study("replan", all_modes, (0.5, 1.0, 2.0, 5.0, 10.0), (200.0,), ("linear",), (0.3,), (2048,), few),
        Study("rtc_grid", all_modes, (1.0,), (200.0,), ("reversal",), (0.2,), (2048,), few,
              d_steps=(0, 1, 2, 4, 8, 16, 20), s_steps=(1, 2, 4, 8)),
        Study("bins", ("open_loop", "hybrid"), (1.0,), (200.0,), ("static",), (0.0,), (64, 256, 1024, 2048, 8192, 0), few),
        Study("perception", ("hybrid",), (1.0,), (200.0,), ("linear",), (0.2,), (2048,), few, PERCEPTIONS),
    ]


def task_grid(task: str, quick: bool = False, seeds: int = 10) -> list[Study]:
    """The grid of a contact task (``--task``): open_loop vs hybrid at 1 Hz, 200 ms, expert lead velocity.

    - pick: static, linear at 0.2 and 0.4 m/s, reversal and jump at 0.2 m/s;
    - insert: the table the seed asks for, a static fixture: bins (256, 1024, 2048, 8192) x clearance (3, 1, 0.5,
      0.25 mm) x sensing noise (0, 2 mm) x mode (open_loop, hybrid) x compliance (off, on)."""
    modes = ("open_loop", "hybrid")
    s = tuple(range(2 if quick else seeds))
    if task == "pick":
        if quick:
            return [Study("pick", modes, (1.0,), (200.0,), ("static", "linear"), (0.2,), (2048,), s, task="pick")]
        return [Study("pick", modes, (1.0,), (200.0,), ("static",), (0.0,), (2048,), s, task="pick"),
                Study("pick", modes, (1.0,), (200.0,), ("linear",), (0.2, 0.4), (2048,), s, task="pick"),
                Study("pick", modes, (1.0,), (200.0,), ("reversal", "jump"), (0.2,), (2048,), s, task="pick")]
    if task == "insert":
        if quick:
            return [Study("insert", modes, (1.0,), (200.0,), ("static",), (0.0,), (2048,), s, task="insert",
                          clearance_mm=(1.0,), noise_m=(0.002,), compliance=(False, True))]
        return [Study("insert", modes, (1.0,), (200.0,), ("static",), (0.0,), (256, 1024, 2048, 8192), s,
                      task="insert", clearance_mm=(3.0, 1.0, 0.5, 0.25), noise_m=(0.0, 0.002),
                      compliance=(False, True))]
    return default_grid(quick, seeds)


def cell_key(cell: dict, duration_s: float) -> str:
    text = json.dumps({**{k: cell.get(k) for k in AXES if k not in ("study", "perception")}, "duration_s": duration_s,
                       **({k: cell.get(k) for k in TASK_AXES} if cell.get("task", "reach") != "reach" else {}),
                       **({"close_at_grasp": True} if cell.get("close_at_grasp") else {}),  # off: the keys as before
                       **({"perception": cell["perception"]} if cell.get("perception", "oracle") != "oracle" else {}),
                       **({"source": cell["source"], "checkpoint": cell.get("checkpoint")}
                          if cell.get("source", "expert") != "expert" else {}),
                       **({"source_args": cell["source_args"]} if cell.get("source_args") else {}),
                       **({"preset": cell["preset"]} if cell.get("preset") else {})}, sort_keys=True)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


# ---- the study's other parts live beside this module: one cell (``cells``), the backends (``backends``), the
# command line and results.csv (``cli``); every name stays importable from here. (The docstring above is the
# command line's description.)
from scenarios.sweep.cells import _CACHE, _run_and_store, _source_and_world, _task_stack, run_cell  # noqa: E402,F401
from scenarios.sweep.backends import run_local, run_ray  # noqa: E402
from scenarios.sweep.cli import main, write_csv  # noqa: E402

__all__ = ["AXES", "FAMILIES", "LEADS", "PERCEPTIONS", "STEP_S", "TASK_AXES", "Study", "cell_key", "default_grid",
           "main", "run_cell", "run_local", "run_ray", "task_grid", "write_csv"]

if __name__ == "__main__":
    sys.exit(main())
