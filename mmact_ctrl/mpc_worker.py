"""Where the MPC is solved: never on the 1 kHz path.

The controller hands each MPC problem to a worker (:meth:`submit`, at the MPC rate) and the QP tracks the newest
plan that has finished (:meth:`poll`). Two workers:

- :class:`InlineMPC` (simulated time): the plan is solved when it is asked for and is ready at once, as if a solver
  beside the loop had answered instantly; deterministic (no wall-clock deadline). Its solve time is recorded apart
  from the control tick (``solve_us``), because on a robot it is not spent on the 1 kHz path.
- :class:`ThreadedMPC` (real time): a thread solves while the 1 kHz loop goes on; a plan is used from the tick
  after it finished. A problem asked for while the previous one is still being solved waits (only the newest is
  kept); a plan that took longer than ``max_solve_ms`` is late: counted and discarded, and the QP keeps the plan it
  has (the fallback ``mpc_late`` models), exactly as a late solve was handled inline before.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Callable

from controllers.mpc import MPCPlan, TaskSpaceMPC


class InlineMPC:
    """Solve at once (simulated time). ``solve_us``: the wall time of each solve, us (kept off the tick's time)."""

    def __init__(self, mpc: TaskSpaceMPC) -> None:
        self.mpc = mpc
        self.solve_us: list[float] = []
        self.late = 0
        self._done: tuple[float, MPCPlan] | None = None

    def reset(self) -> None:
        self.mpc.reset()
        self.solve_us = []
        self.late = 0
        self._done = None

    def submit(self, t_s: float, args: tuple) -> None:
        t0 = time.perf_counter()
        plan = self.mpc.solve(t_s, *args)  # looked up now: a fault injector may have patched it
        self.solve_us.append((time.perf_counter() - t0) * 1e6)
        self._done = (t_s, plan)

    def poll(self) -> tuple[float, MPCPlan] | None:
        """The newest finished ``(request time, plan)`` not yet taken, or None."""
        done, self._done = self._done, None
        return done

    def close(self) -> None:
        pass


class ThreadedMPC:
    """Solve in a thread beside the loop (real time).

    Args:
        mpc: the MPC (only this worker's thread calls its ``solve`` while the worker runs).
        max_solve_ms: a plan that finished later than this after its request is late: counted, discarded.
        clock: wall clock, s (for tests).
    """

    def __init__(self, mpc: TaskSpaceMPC, max_solve_ms: float, clock: Callable[[], float] = time.perf_counter) -> None:
        if not max_solve_ms > 0:
            raise ValueError(f"max_solve_ms must be > 0, got {max_solve_ms!r}")
        self.mpc = mpc
        self.max_solve_s = float(max_solve_ms) / 1e3 if math.isfinite(max_solve_ms) else math.inf
        self._clock = clock
        self._cv = threading.Condition()
        self._request: tuple[float, tuple, float] | None = None
        self._done: tuple[float, MPCPlan] | None = None
        self._busy = False
        self._stop = False
        self.solve_us: list[float] = []
        self.late = 0
        self.superseded = 0  # requests replaced by a newer one before the thread took them
        self.errors = 0
        self._thread = threading.Thread(target=self._run, name="mpc-worker", daemon=True)
        self._thread.start()

    def reset(self) -> None:
        with self._cv:
            while self._busy:  # a solve in flight finishes first: reset never races the solver's state
                self._cv.wait()
            self._request = None
            self._done = None
            self.mpc.reset()
            self.solve_us, self.late, self.superseded, self.errors = [], 0, 0, 0

    def submit(self, t_s: float, args: tuple) -> None:
        with self._cv:
            if self._request is not None:
                self.superseded += 1
            self._request = (t_s, args, self._clock())
            self._cv.notify_all()

    def poll(self) -> tuple[float, MPCPlan] | None:
        with self._cv:
            done, self._done = self._done, None
        return done

    def _run(self) -> None:
        while True:
            with self._cv:
                while self._request is None and not self._stop:
                    self._cv.wait()
                if self._stop:
                    return
                t_s, args, asked_s = self._request
                self._request = None
                self._busy = True
            t0 = self._clock()
            try:
                plan = self.mpc.solve(t_s, *args)
            except Exception:  # noqa: BLE001 - the MPC's own fallback covers solver errors; anything else: no plan
                plan = None
            t1 = self._clock()
            with self._cv:
                self._busy = False
                self.solve_us.append((t1 - t0) * 1e6)
                if plan is None:
                    self.errors += 1
                elif t1 - asked_s > self.max_solve_s:
                    self.late += 1  # the QP keeps the plan it has
                else:
                    self._done = (t_s, plan)
                self._cv.notify_all()

    def close(self) -> None:
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        self._thread.join(timeout=1.0)
