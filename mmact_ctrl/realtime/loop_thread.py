"""The loop thread's real-time settings while an episode runs: SCHED_FIFO, a CPU of its own, no cyclic GC, a short
GIL switch interval; everything restored afterwards (used by the real-time session and by the host check)."""

from __future__ import annotations

import contextlib
import gc
import os
import sys
from dataclasses import dataclass


@dataclass
class LoopThreadState:
    """What :func:`loop_thread` could set: ``priority_refused`` says why SCHED_FIFO was refused ('' when granted or
    not asked for)."""

    priority_refused: str = ""


@contextlib.contextmanager
def loop_thread(fifo_priority: int = 0, loop_cpus: set[int] | None = None, switch_interval_s: float | None = None,
                no_gc: bool = True):
    """Run the body with this thread under SCHED_FIFO at ``fifo_priority`` (> 0; best effort, refused: normal
    scheduling and ``state.priority_refused`` says so), pinned to ``loop_cpus`` (empty or None: not pinned), with
    Python's GIL switch interval ``switch_interval_s`` (None: unchanged) and the cyclic GC off (``no_gc``: a full
    collection takes milliseconds; one runs before). Yields a :class:`LoopThreadState`."""
    state = LoopThreadState()
    old_interval = sys.getswitchinterval()
    if switch_interval_s is not None:
        sys.setswitchinterval(switch_interval_s)
    restore_priority = _raise_priority(fifo_priority, state)
    old_cpus = os.sched_getaffinity(0) if loop_cpus else None
    if loop_cpus:
        os.sched_setaffinity(0, loop_cpus)
    gc_was = gc.isenabled()
    if no_gc:
        gc.collect()
        gc.disable()
    try:
        yield state
    finally:
        if gc_was:
            gc.enable()
        restore_priority()
        if old_cpus:
            os.sched_setaffinity(0, old_cpus)
        sys.setswitchinterval(old_interval)


def _raise_priority(prio: int, state: LoopThreadState):
    """SCHED_FIFO ``prio`` for this thread; returns the function that restores the old policy."""
    if prio <= 0 or not hasattr(os, "sched_setscheduler"):
        return lambda: None
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
    except OSError as exc:
        state.priority_refused = f"SCHED_FIFO {prio} refused: {exc}"
        return lambda: None
    return lambda: os.sched_setscheduler(0, policy, param)


def cpu_split(loop_cpu: int | None) -> tuple[set[int], set[int]]:
    """(the loop's CPUs, the workers' CPUs) of this process's allowed set (both empty: no pinning)."""
    if loop_cpu is None or not hasattr(os, "sched_getaffinity"):
        return set(), set()
    allowed = os.sched_getaffinity(0)
    if len(allowed) < 2 or loop_cpu not in allowed:
        return set(), set()
    return {loop_cpu}, allowed - {loop_cpu}
