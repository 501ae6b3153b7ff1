"""Where the MPC is solved: never on the 1 kHz path.

The controller hands each MPC problem to a worker (:meth:`submit`, at the MPC rate) and the QP tracks the newest
plan that has finished (:meth:`poll`). Two workers:

- :class:`InlineMPC` (simulated time): the plan is solved when it is asked for and is ready at once, as if a solver
  beside the loop had answered instantly; deterministic (no wall-clock deadline). Its solve time is recorded apart
  from the control tick (``solve_us``), because on a robot it is not spent on the 1 kHz path.
- :class:`DeferredMPC` (simulated time, ``StackConfig.mpc_delay_s``): a process of its own solves while the loop
  goes on, and the plan asked for at ``t`` is taken at the first tick at or after ``t + delay`` in simulated time
  (the loop waits for it there if it has not come back): deterministic, whatever the load, and the solve is off the
  loop's thread. With a delay of 0 it gives the inline results bit for bit (the loop then waits for every plan).
- :class:`ProcessMPC` (real time): a process of its own solves while the 1 kHz loop goes on; a plan is used from
  the tick it has come back. A problem asked for while the previous one is still being solved waits (only the
  newest is kept); a plan that took longer than ``max_solve_ms`` is late: counted and discarded, and the QP keeps the
  plan it has (the fallback ``mpc_late`` models), exactly as a late solve was handled inline before.
"""

from __future__ import annotations

import math
import time
from typing import Callable

import numpy as np

from controllers.mpc import MPCPlan, TaskSpaceMPC


class InlineMPC:
    """Solve at once (simulated time). ``solve_us``: the wall time of each solve, us (kept off the tick's time)."""

    def __init__(self, mpc: TaskSpaceMPC) -> None:
        self.mpc = mpc
        self.solve_us: list[float] = []
        self._done: tuple[float, MPCPlan] | None = None

    @property
    def failures(self) -> int:
        """Solver failures (the MPC's own count)."""
        return self.mpc.failures

    @property
    def late(self) -> int:
        """Late solves (none in simulated time, but those a fault injects: ``mpc_late``)."""
        return self.mpc.late

    def reset(self) -> None:
        self.mpc.reset()
        self.solve_us = []
        self._done = None

    def submit(self, t_s: float, args: tuple) -> None:
        t0 = time.perf_counter()
        plan = self.mpc.solve(t_s, *args)  # looked up now: a fault injector may have patched it
        self.solve_us.append((time.perf_counter() - t0) * 1e6)
        self._done = (t_s, plan)

    def poll(self, t_s: float | None = None) -> tuple[float, MPCPlan] | None:
        """The newest finished ``(request time, plan)`` not yet taken, or None (``t_s``, the tick's time: unused)."""
        done, self._done = self._done, None
        return done

    def close(self) -> None:
        pass


def _serve_mpc(conn, config, q_nominal_rad) -> None:
    """The MPC process: build the MPC, then answer ``("solve", t_s, args)`` with ``(t_s, plan, solve_us, failures)``
    and ``("reset",)`` with ``("reset",)`` until ``("stop",)`` or the pipe closes."""
    import os

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    mpc = TaskSpaceMPC(config, q_nominal_rad=q_nominal_rad)
    conn.send(("ready",))
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        if msg[0] == "stop":
            return
        if msg[0] == "reset":
            mpc.reset()
            conn.send(("reset",))
            continue
        _, t_s, args = msg
        t0 = time.perf_counter()
        try:
            plan = mpc.solve(t_s, *args)
        except Exception:  # noqa: BLE001 - bad inputs: no plan (the QP keeps the one it has)
            plan = None
        conn.send((t_s, plan, (time.perf_counter() - t0) * 1e6, mpc.failures))


def _start_process(config, q_nominal_rad):
    """``(connection, process)`` of a fresh MPC process (:func:`_serve_mpc`), once it has built its MPC."""
    import multiprocessing as mp
    from dataclasses import replace

    ctx = mp.get_context("spawn")  # a fresh interpreter: no copy of the parent's renderer, threads or sockets
    conn, child = ctx.Pipe(duplex=True)
    proc = ctx.Process(target=_serve_mpc, args=(child, replace(config, max_solve_ms=math.inf),
                                                np.asarray(q_nominal_rad, dtype=float)),
                       name="mpc-process", daemon=True)
    proc.start()
    child.close()
    if not conn.poll(60.0) or conn.recv()[0] != "ready":
        raise RuntimeError("the MPC process did not start")
    return conn, proc


def _stop_process(conn, proc) -> None:
    try:
        conn.send(("stop",))
    except (BrokenPipeError, OSError):
        pass
    proc.join(timeout=2.0)
    if proc.is_alive():
        proc.kill()


class DeferredMPC:
    """Solve in a process of its own beside the loop, in simulated time: the plan asked for at ``t_s`` is taken at
    the first tick at or after ``t_s + delay_s`` (:meth:`poll` with the tick's time), waiting for it there if it
    has not come back. Every problem is solved, in order (none superseded, none late): the results depend on the
    delay, never on the machine's load. What it buys: the solve (about a fifth of an episode's wall time on the
    loop's thread with the MPC inline) runs on the other core while the loop goes on; what it costs: the plan starts
    from the state ``delay_s`` old (0: the inline results bit for bit, and no speed-up: the loop waits for each).

    A fault injected into the parent's MPC object (``scenarios.faults``' ``mpc_late``) does not reach the process:
    the fault suite runs the MPC inline.

    Args:
        config: the MPC's configuration (the process builds its own, ~0.3 s, plus the imports: 1-3 s).
        q_nominal_rad: the posture its null-space term pulls toward.
        delay_s: how long after it was asked for a plan is taken, s (simulated time).
    """

    #: the plan tracker blends a plan in from the tick it is taken, not from the one it was asked at: every plan
    #: here comes ``delay_s`` late, and one a whole blend (20 ms) old would otherwise step in
    blends_from_take = True

    def __init__(self, config, q_nominal_rad, delay_s: float) -> None:
        if not (math.isfinite(delay_s) and delay_s >= 0):
            raise ValueError(f"delay_s must be a finite time >= 0 s, got {delay_s!r}")
        self.delay_s = float(delay_s)
        self._conn, self._proc = _start_process(config, q_nominal_rad)
        self._asked: list[float] = []  # the simulated times of the problems in flight, oldest first
        self.solve_us: list[float] = []
        self.failures = 0
        self.errors = 0  # problems that came back without a plan, or a process that died (the QP keeps its plan)
        self.late = 0  # never in simulated time (the loop waits): kept for the counters

    def reset(self) -> None:
        self._drain()
        if self._proc.is_alive():
            try:
                self._conn.send(("reset",))
                while self._conn.recv()[0] != "reset":
                    pass
            except (EOFError, OSError):
                self.errors += 1
        self.solve_us, self.failures, self.errors, self.late = [], 0, 0, 0

    def submit(self, t_s: float, args: tuple) -> None:
        try:
            self._conn.send(("solve", t_s, args))
        except (BrokenPipeError, OSError):  # the process is gone: no plan (the QP keeps the one it has)
            self.errors += 1
            return
        self._asked.append(float(t_s))

    def poll(self, t_s: float | None = None) -> tuple[float, MPCPlan] | None:
        """The newest plan due at ``t_s`` (asked for at least ``delay_s`` before it), waiting for it if it has not
        come back; None when none is due. ``t_s`` None: none is due."""
        done = None
        while self._asked and t_s is not None and self._asked[0] + self.delay_s <= t_s + 1e-9:
            self._asked.pop(0)
            got = self._receive()
            if got is not None:
                done = got
        return done

    def _receive(self) -> tuple[float, MPCPlan] | None:
        try:
            t_s, plan, solve_us, failures = self._conn.recv()
        except (EOFError, OSError):
            self.errors += 1
            return None
        self.solve_us.append(solve_us)
        self.failures = failures
        if plan is None:
            self.errors += 1
            return None
        return t_s, plan

    def _drain(self) -> None:
        while self._asked:
            self._asked.pop(0)
            self._receive()

    def close(self) -> None:
        self._asked = []
        _stop_process(self._conn, self._proc)


class ProcessMPC:
    """Solve in a process of its own beside the loop (real time). A thread would not do: the solver holds the GIL,
    which stalled the 1 kHz thread for the whole solve (measured here: every solve blocked it 0.5 ms or more, up to
    12-20 ms on the loaded machine).

    The newest problem is sent when the previous plan has come back (one in flight; a problem asked for meanwhile
    replaces the waiting one: ``superseded``); a plan that comes back later than ``max_solve_ms`` after it was asked
    for is late: counted, discarded, and the QP keeps the plan it has.

    Args:
        config: the MPC's configuration (the process builds its own, ~0.3 s, plus the imports).
        q_nominal_rad: the posture its null-space term pulls toward.
        max_solve_ms: the lateness bound (default ``config.max_solve_ms``).

    In real time the runner's deadline order (``mmact_ctrl.tick_order.DeadlineOrder``) hands each problem over once
    the tick's command is out: the process then solves while the loop sleeps, not while it computes (measured here: a
    solve running beside the tick's own work made that work 1.5-2x slower).
    """

    def __init__(self, config, q_nominal_rad, max_solve_ms: float | None = None,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        limit = config.max_solve_ms if max_solve_ms is None else max_solve_ms
        if not limit > 0:
            raise ValueError(f"max_solve_ms must be > 0, got {limit!r}")
        self.max_solve_s = float(limit) / 1e3 if math.isfinite(limit) else math.inf
        self._clock = clock
        self._conn, self._proc = _start_process(config, q_nominal_rad)
        self._asked: float | None = None  # wall time of the problem in flight
        self._waiting: tuple[float, tuple] | None = None
        self.solve_us: list[float] = []
        self.late = 0
        self.failures = 0
        self.superseded = 0
        self.errors = 0

    def reset(self) -> None:
        while self._asked is not None:  # let the solve in flight come back first
            self.poll(block=True)
        self._waiting = None
        self._conn.send(("reset",))
        while self._conn.recv()[0] != "reset":
            pass
        self.solve_us, self.late, self.failures, self.superseded, self.errors = [], 0, 0, 0, 0

    def submit(self, t_s: float, args: tuple) -> None:
        if self._asked is None:
            self._conn.send(("solve", t_s, args))
            self._asked = self._clock()
        else:
            if self._waiting is not None:
                self.superseded += 1
            self._waiting = (t_s, args)

    def poll(self, block: bool = False, t_s: float | None = None) -> tuple[float, MPCPlan] | None:
        """The plan that has come back, if in time (else counted late and None); sends the waiting problem (``t_s``,
        the tick's simulated time: unused, the wall clock decides)."""
        if self._asked is None or not self._conn.poll(None if block else 0):
            return None
        t_s, plan, solve_us, failures = self._conn.recv()
        late = self._clock() - self._asked > self.max_solve_s
        self._asked = None
        self.solve_us.append(solve_us)
        self.failures = failures
        if self._waiting is not None:
            t_next, args = self._waiting
            self._waiting = None
            self.submit(t_next, args)
        if plan is None:
            self.errors += 1
            return None
        if late:
            self.late += 1
            return None
        return t_s, plan

    def close(self) -> None:
        _stop_process(self._conn, self._proc)
