"""Fault injectors: one small wrapper per fault, built fresh per episode from a :class:`FaultSpec`.

Each fault wraps one part of the stack and leaves everything else untouched:

- the chunk source (:class:`FaultySource`, ``scenarios.faults.source_faults``): it raises, builds a NaN chunk,
  answers garbage tokens, answers a chunk that starts 25 cm away, falls silent, or answers late;
- the world's perception (:class:`FaultyPerception`, ``scenarios.faults.world_faults``): dropped, frozen, outlier
  or non-finite measurements;
- the world itself (:class:`MovedTarget`): the instructed ball is moved (its MuJoCo mocap body, so the camera,
  the measurements and the log all see it) out of reach, or to the edge of the workspace;
- the controller's solvers (:func:`qp_fail_burst`, :func:`mpc_late`, ``scenarios.faults.controller_faults``): the
  real, counted fallback paths are forced for a while;
- the wire (``wire_*``, ``scenarios.faults.wire``): the source served over openpi's protocol on 127.0.0.1, the
  server raising (an error frame), slow past the client's timeout, answering wrong shapes or NaN, or dying and
  coming back;
- the command link (:class:`DroppedTicks`): a :class:`~mmact_ctrl.loop.CommandLink` that drops ticks;
- the initial state (``start_with_velocity``).

Wrappers delegate every other attribute to the wrapped object (``__getattr__``). :func:`inject` builds the
wrappers of one fault for one episode and returns an :class:`Injection` (use it as a context manager: patches
of the controller's solvers are removed on exit); :func:`run_fault_episode` runs one episode under a fault.

The registry :data:`FAULTS` (``scenarios.faults.registry``) maps each public fault name to its :class:`Fault`;
:class:`FaultSpec`, :class:`Fault` and :class:`Injection` live in ``scenarios.faults.spec``. Every name is
importable from here.
"""

from __future__ import annotations

from scenarios.faults.controller_faults import DroppedTicks, dropped_ticks, mpc_late, qp_fail_burst
from scenarios.faults.registry import FAULTS
from scenarios.faults.source_faults import GARBAGE_TOKEN, SPLICE_OFFSET_M, FaultySource, source_fault, wire_fault
from scenarios.faults.spec import DEFAULT_ONSET_S, DEFAULT_WINDOW_S, Fault, FaultSpec, Injection
from scenarios.faults.world_faults import (
    NEAR_SINGULAR_POS_M,
    SHOULDER_POS_M,
    START_DQ_RAD_S,
    UNREACHABLE_POS_M,
    FaultyPerception,
    MovedTarget,
    moved_target,
    perception_fault,
    start_with_velocity,
)

__all__ = [
    "DEFAULT_ONSET_S", "DEFAULT_WINDOW_S", "SPLICE_OFFSET_M", "UNREACHABLE_POS_M", "SHOULDER_POS_M",
    "NEAR_SINGULAR_POS_M", "START_DQ_RAD_S", "GARBAGE_TOKEN", "FAULTS", "Fault", "FaultSpec", "Injection",
    "FaultySource", "FaultyPerception", "MovedTarget", "DroppedTicks", "source_fault", "wire_fault",
    "perception_fault", "moved_target", "dropped_ticks", "start_with_velocity", "qp_fail_burst", "mpc_late",
    "inject", "run_fault_episode",
]


def inject(spec: FaultSpec, world, source, controller) -> Injection:
    """The wrapped world, source, link and initial velocity of one episode under ``spec`` (wrappers built fresh;
    solver patches are made on ``controller`` and removed by ``Injection.close()``)."""
    inj = Injection(spec=spec, world=world, source=source, window_s=spec.window_s(controller.config.dt_s))
    try:
        spec.fault.build(spec, world, source, controller, inj)
    except Exception:
        inj.close()
        raise
    return inj


def run_fault_episode(spec: FaultSpec, world, source, controller, seed: int, **kwargs):
    """One episode of ``controller.config.duration_s`` under the fault; returns ``(log, injection)``."""
    from mmact_ctrl.loop import run_episode

    with inject(spec, world, source, controller) as inj:
        log = run_episode(inj.world, inj.source, controller, seed, link=inj.link,
                          initial_dq_rad_s=inj.initial_dq_rad_s, **kwargs)
    return log, inj
