"""The 1 kHz loop on the wall clock, and its deadline statistics (named as ros2_control and libfranka name them).

:class:`WallClockPacer` runs an :class:`~mmact_ctrl.runner.EpisodeRunner` one tick per period: tick ``k`` is due at
``t_start + k * dt`` (deadline-based: no drift however long the episode), the pacer sleeps until shortly before it
and spins the rest. The tick's command must be ready before its cycle ends (``due + dt``); one that is later never
reaches the robot (the runner's ``deadline`` hook: the robot re-applies the last torque, counted, and 20 in a row
abort as on a Panda). A late tick is not skipped: the physics of the simulated world is stepped by this loop, so the
ticks after a stall run back to back until the loop is on time again, each with the torque the robot really held.

Statistics (:func:`deadline_stats`), per episode:

``overruns``                   ticks whose work ended after their deadline (their command was late);
``overrun_rate``               the same as a share of the ticks;
``cycles_missed``              ticks that started a whole period or more after they were due (ros2_control's
                               "missed cycles");
``exec_us``                    the work of a tick (perception, chunk admission, control, safety check, physics
                               step): median / p99 / max, us;
``jitter_us``                  how late each tick started: mean / std / p99 / max, us;
``control_command_success_rate``  libfranka's share of commands received, the minimum over windows of 100 ticks;
``realtime_rate``              simulated time over wall time (Drake's ``get_actual_realtime_rate``; 1.0 on time).

Per tick the pacer also keeps the loop thread's CPU time over the tick's work (``cpu_us``): equal to the work's wall
time, the thread ran the whole time (a slow tick had more to do, or the CPU ran slowly: a contended host); much less,
it waited (preempted, or another thread held the GIL).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class PacerConfig:
    """Attributes:
    spin_s: the pacer sleeps until this long before a tick is due and spins the rest, s (Linux wakes a sleeper
        about 0.05-0.1 ms late).
    window_ticks: the window of ``control_command_success_rate`` (libfranka: the last 100 commands).
    start_delay_s: wall time between the start call and the first tick (lets the workers settle), s.
    """

    spin_s: float = 0.0003
    window_ticks: int = 100
    start_delay_s: float = 0.02

    def __post_init__(self) -> None:
        if not (0 <= self.spin_s < 0.01):
            raise ValueError(f"spin_s must be in [0, 0.01) s, got {self.spin_s!r}")
        if self.window_ticks < 1:
            raise ValueError(f"window_ticks must be >= 1, got {self.window_ticks!r}")
        if not self.start_delay_s >= 0:
            raise ValueError(f"start_delay_s must be >= 0, got {self.start_delay_s!r}")


class WallClockPacer:
    """Paces a runner's ticks at their wall-clock times; is also the runner's ``deadline`` (``missed(k)``).

    Args:
        dt_s: the control period, s.
        config: pacing settings.
        clock: wall clock, s (monotonic).
        sleep: how to wait (tests may pass a fake).
    """

    def __init__(self, dt_s: float, config: PacerConfig = PacerConfig(),
                 clock: Callable[[], float] = time.perf_counter, sleep: Callable[[float], None] = time.sleep,
                 cpu_clock: Callable[[], float] = time.thread_time) -> None:
        if not dt_s > 0:
            raise ValueError(f"dt_s must be > 0, got {dt_s!r}")
        self.dt_s, self.config, self._clock, self._sleep = float(dt_s), config, clock, sleep
        self._cpu_clock = cpu_clock  # this thread's CPU time, s (0.4 us a call here)
        self._due_s = math.inf
        self._late_k: list[int] = []
        #: an injected delay added to the work of the ticks it names (k -> s), for tests of the overrun path
        self.stall_s: dict[int, float] = {}

    def missed(self, k: int) -> bool:
        """Whether tick ``k``'s command is ready after its cycle ended (called by the runner once it is computed)."""
        stall = self.stall_s.get(k)
        if stall:
            end = self._clock() + stall
            while self._clock() < end:  # a tick that really takes longer (busy, as a slow solver would be)
                pass
        late = self._clock() > self._due_s + self.dt_s
        if late:
            self._late_k.append(k)
        return late

    def run(self, runner) -> dict:
        """Run ``runner`` to its end on the wall clock; returns :func:`deadline_stats` (also set as
        ``runner.log.deadline`` once the runner finishes)."""
        n = runner.n_ticks - runner.k
        dt, clock, spin, cpu_clock = self.dt_s, self._clock, self.config.spin_s, self._cpu_clock
        start = np.zeros(n)
        end = np.zeros(n)
        cpu = np.zeros(n)
        due0 = clock() + self.config.start_delay_s
        self._late_k = []
        k0 = runner.k
        done = 0
        for i in range(n):
            due = due0 + i * dt
            now = clock()
            if now < due - spin:
                self._sleep(due - spin - now)
            while clock() < due:
                pass
            self._due_s = due
            start[i] = clock() - due
            c0 = cpu_clock()
            runner.advance((k0 + i + 1) * dt)
            cpu[i] = cpu_clock() - c0
            end[i] = clock() - due
            done = i + 1
            if runner.done:
                break
        wall_s = clock() - due0
        late = np.asarray(self._late_k, dtype=int) - k0
        stats = deadline_stats(start[:done], end[:done], dt, late, self.config.window_ticks, wall_s)
        self._due_s = math.inf
        #: per tick of the last run: the work (us), the thread's CPU time in it (us), how late it started (us), the
        #: ticks whose command was late
        self.exec_us = (end[:done] - start[:done]) * 1e6
        self.cpu_us = cpu[:done] * 1e6
        self.jitter_us = start[:done] * 1e6
        self.late_ticks = late
        return stats


def deadline_stats(start_late_s: np.ndarray, end_late_s: np.ndarray, dt_s: float, late_ticks: np.ndarray,
                   window_ticks: int, wall_s: float) -> dict:
    """The statistics of the module docstring from each tick's start and end relative to its due time (s) and the
    ticks whose command was late."""
    n = len(start_late_s)
    if n == 0:
        return {"ticks": 0}
    exec_us = (end_late_s - start_late_s) * 1e6
    jitter_us = start_late_s * 1e6
    delivered = np.ones(n)
    late = late_ticks[(late_ticks >= 0) & (late_ticks < n)]
    delivered[late] = 0.0
    w = min(window_ticks, n)
    rates = np.convolve(delivered, np.ones(w) / w, mode="valid")
    return {
        "ticks": int(n),
        "overruns": int(len(late)),
        "overrun_rate": float(len(late) / n),
        "cycles_missed": int(np.count_nonzero(start_late_s >= dt_s)),
        "exec_us": {"median": float(np.median(exec_us)), "p99": float(np.percentile(exec_us, 99)),
                    "max": float(np.max(exec_us))},
        "jitter_us": {"mean": float(np.mean(jitter_us)), "std": float(np.std(jitter_us)),
                      "p99": float(np.percentile(jitter_us, 99)), "max": float(np.max(jitter_us))},
        "control_command_success_rate": float(np.min(rates)),
        "realtime_rate": float(n * dt_s / wall_s) if wall_s > 0 else float("nan"),
    }
