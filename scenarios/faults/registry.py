"""The registry of faults: :data:`FAULTS` maps each public fault name to its :class:`~scenarios.faults.spec.Fault`
(kind, one line for reports, the builder that wraps one part of the stack, its default window)."""

from __future__ import annotations

import math

from scenarios.faults.controller_faults import dropped_ticks, mpc_late, qp_fail_burst
from scenarios.faults.source_faults import SPLICE_OFFSET_M, source_fault, wire_fault
from scenarios.faults.spec import Fault, Injection
from scenarios.faults.world_faults import (
    NEAR_SINGULAR_POS_M,
    UNREACHABLE_POS_M,
    moved_target,
    perception_fault,
    start_with_velocity,
)


def _nothing(spec, world, source, controller, inj: Injection) -> None:
    pass


def _registry() -> dict[str, Fault]:
    faults = [
        Fault("none", "baseline", "no fault (baseline)", _nothing, duration_s=0.0),
        Fault("source_raises", "source", "plan raises RuntimeError for 1.5 s", source_fault("raise")),
        Fault("nan_chunk", "source", "the source builds a chunk with NaN waypoints (ActionChunk raises) for 1.5 s",
              source_fault("nan")),
        Fault("garbage_tokens", "source", "chunks carry token ids 1e9 or float tokens for 1.5 s", source_fault("tokens")),
        Fault("splice_offset", "source", f"chunks offset by {SPLICE_OFFSET_M} m for 1.5 s", source_fault("splice")),
        Fault("source_silent_0.1s", "source", "the source answers nothing for 0.1 s", source_fault("silent"),
              duration_s=0.1),
        Fault("source_silent_1.5s", "source", "the source answers nothing for 1.5 s", source_fault("silent"),
              duration_s=1.5),
        Fault("source_silent_3s", "source", "the source answers nothing for 3 s", source_fault("silent"),
              duration_s=3.0),
        Fault("latency_spike_10x", "source", "chunks arrive 10x the configured latency late for 1.5 s",
              source_fault("late")),
        Fault("perception_dropout_50", "perception", "half the measurements missing for 1.5 s",
              perception_fault("dropout")),
        Fault("perception_frozen", "perception", "the measurement frozen (bit-identical) for 1.5 s",
              perception_fault("frozen")),
        Fault("perception_outlier", "perception", "10 % of the measurements 10 sigma off for 1.5 s",
              perception_fault("outlier")),
        Fault("perception_nan", "perception", "every 5th measurement NaN, every 7th inf for 1.5 s",
              perception_fault("nan")),
        Fault("qp_fail_burst", "controller", "50 ticks of QP fallback", qp_fail_burst, ticks=50),
        Fault("mpc_late", "controller", "every MPC solve late for 0.5 s (hybrid only)", mpc_late, duration_s=0.5),
        *[Fault(f"missed_ticks_{n}", "link", f"{n} consecutive ticks not delivered", dropped_ticks(n), ticks=n)
          for n in (1, 5, 19, 20)],
        Fault("start_with_velocity", "world", "the arm starts moving (0.6 rad/s on joints 1, 2, 4)",
              start_with_velocity, duration_s=0.0),
        Fault("unreachable_target", "world", "the ball moves 1.3 m in front of the base at the onset",
              moved_target(UNREACHABLE_POS_M), duration_s=math.inf, unreachable=True),
        Fault("near_singularity", "world", "the ball moves 0.85 m straight out from the shoulder at the onset",
              moved_target(NEAR_SINGULAR_POS_M), duration_s=math.inf),
        Fault("wire_error_frame", "wire", "the policy server raises: an error (text) frame, connection closed, for 1.5 s",
              wire_fault("error_frame")),
        Fault("wire_slow", "wire", "the policy server answers after the client's request timeout for 1.5 s",
              wire_fault("slow")),
        Fault("wire_bad_shape", "wire", "the policy server answers actions of the wrong shape for 1.5 s",
              wire_fault("bad_shape")),
        Fault("wire_nan", "wire", "the policy server answers NaN actions for 1.5 s", wire_fault("nan")),
        Fault("wire_server_dies", "wire", "the policy server stops at the onset (port closed), back after 1.5 s",
              wire_fault("dies")),
    ]
    return {f.name: f for f in faults}


#: every fault by its public name.
FAULTS: dict[str, Fault] = _registry()
