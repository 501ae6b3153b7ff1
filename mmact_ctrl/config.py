"""Configuration of the hybrid stack: every layer and every time scale is a switch."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from controllers.mpc import MPCConfig
from controllers.qp_id import QPConfig
from controllers.retarget import RetargetConfig
from controllers.smoother import SmootherConfig
from controllers.target_estimator import EstimatorConfig

from mmact_ctrl.control.force_guard import YIELD_M_S_PER_N
from mmact_ctrl.executors.registry import MODES, check_mode

#: the built-in ways of executing chunks (``mmact_ctrl.executors.registry.MODES``: baselines first, ours last); the
#: modes that execute chunks without our control layer (the baselines from the field):
BASELINE_MODES: tuple[str, ...] = tuple(m for m in MODES if m != "hybrid")


@dataclass(frozen=True)
class StackConfig:
    """How chunks are executed.

    Attributes:
        mode: how chunks are executed. ``open_loop``: each chunk's dequantized waypoints are
            interpolated and tracked by the QP, nothing else, replanning on the clock at ``replan_hz``;
            ``receding``: the first ``receding_k`` waypoints of each chunk run, then the source is
            queried again (Diffusion Policy style: replanning is paced by execution, not the clock);
            ``temporal_ensemble``: overlapping chunks are averaged with exponential weights, the oldest
            weighing most (ACT); ``inpaint``: real-time chunking: the waypoints that will run while the
            next chunk is computed are given to the source as known and the rest is filled in, so chunks
            join without a jump; ``residual``: an A2C2-style learned correction from the latest target
            measurements, tracked by the QP; ``hybrid``: ours, Kalman-filtered retargeting + Ruckig + MPC + QP.
            Each is one class in ``mmact_ctrl.executors``.
        residual_checkpoint: residual: the ``policy.residual`` checkpoint ("" = the shipped one).
        use_ruckig: hybrid only: smooth the reference with Ruckig.
        use_mpc: hybrid only: a CasADi MPC between Ruckig and the QP previews the reference
            (retargeted chunk + predicted target) over ``mpc.horizon_steps * mpc.dt_s`` within
            joint limits, re-solved at ``mpc.rate_hz``; the QP tracks its plan.
        retarget: hybrid only: the retargeting rule and trust radius.
        replan_hz: how often the chunk source is queried, Hz.
        latency_ms: inference latency: a chunk observed at t0 becomes active at t0 + latency.
        measured_latency: use each chunk's measured inference time as its latency instead of ``latency_ms``.
        bins: action bins of the tokenizer (0 = no quantization).
        dt_s: physics and control period, s.
        perception_hz: target measurement rate, Hz.
        duration_s: episode length, s.
        receding_k: receding: waypoints executed per chunk before replanning (0: ``1 / (replan_hz * chunk dt)``).
        ensemble_decay_per_s: temporal_ensemble: weight ``exp(-decay * (t0_chunk - t0_oldest))``.
        chunk_timeout_s: stale-chunk watchdog: when no valid chunk has arrived for this long (or the active
            chunk has run out) the reference brakes to rest within the smoother's limits and holds, s.
        splice_radius_m: a chunk whose position at its activation is farther than this from the reference
            being executed is rejected (the previous chunk keeps running), m.
        tcp_floor_m: the lowest height the TCP reference is ever put at, m (world frame; the table top is z = 0):
            a waypoint, correction or target below it is raised to it in every mode (counted in
            ``floor_clamps``). Found with the 3-D policy: a chunk aimed at the table drove the fingers into it,
            and the contact pushed joint 6 past its velocity limit. The fingertips reach about 1 cm below the TCP.
        mpc_plan_start: hybrid with MPC: where each plan starts, ``measured`` (the robot's state) or ``tracked``
            (the previous plan's state now; see ``HybridController._plan_start``).
        plan_resync_m, plan_resync_m_s: ``tracked``: a plan starts from the state being tracked unless the TCP is
            farther than this from it (then from the measured state), m and m/s.
        abort_after_missed_ticks: this many missed control ticks in a row abort the episode, as on the Panda
            (``communication_constraints_violation``).
        mpc_keep_plan_s: hybrid with MPC: after a failed or late solve the last plan is kept this long after the
            last good solve, then the QP tracks the smoothed reference directly until a solve succeeds, s.
        mpc_blend_s: hybrid with MPC: a new plan takes over from the previous one over this long (smoothstep
            blend of the two references; each plan also starts from the state being tracked), s.
        mpc_phase_s: hybrid with MPC: the MPC ticks are at ``mpc_phase_s + n / mpc.rate_hz``. The real-time mode sets
            5 ms, half a 100 Hz perception period, so the MPC's 50 Hz work and the filter's 100 Hz fusion fall on
            different ticks (together they made the slowest ticks); 0 in simulated time keeps the published results.
        mpc_delay_s: hybrid with MPC, simulated time: None (default) solves each plan inline, at the tick that asks
            for it, and that tick tracks it (every published result). A time >= 0, at most one MPC period: the plan
            is solved in a process of its own beside the loop and taken that much later in simulated time
            (``mmact_ctrl.mpc_worker.DeferredMPC``: deterministic whatever the load; 0 gives the inline results
            bit for bit), so the solve leaves the loop's thread, at the cost of a plan that starts from a state that
            old. Call ``HybridController.close()`` when done (the process is a daemon: it ends with the program).
        mpc_preview_governed: hybrid with MPC and a descent band (pick): the MPC's preview is held above the heights
            the descent governor lets the reference reach (``DescentGovernor.lowest_z_m``; README, Contact, point
            10). False: the chunk's own descent, as every pick figure before stop 53 was made (a plan that counted on
            it traded the other axes for it: the open hand came down 12-25 mm off the cube sideways); kept so that the
            faults read on those runs can be reproduced and the bound's effect measured.
        latch_on_grip: the grasp latch (``ChunkStage``: the chunk's correction held while the gripper is commanded
            closed on the object) waits until the fingers are on the object: not while their measured opening is wide
            open or still shrinking at the free closing speed (``mmact_ctrl.control.fingers``; README, Contact, point
            12). False: latched from the closing command, as every pick figure before stop 54 was made (the hand
            went on along the chunk's course for the 0.175 s the fingers take to close, while the object did not).
            Without a measured opening (reach) nothing changes.
        contact_force_limit_n: the largest external force on the robot that is not a violation, N
            (``controllers.contact_safety``: counted on every tick where the world reports a wrench).
        guard_yield_m_s_per_n: how fast the contact-force guard's reference yields per newton over its threshold,
            m/s/N (``mmact_ctrl.control.force_guard``); a task's settings may ask for a faster one.
        empty_hand_after_s: with a descent band, in a mode that reads the object: once the gripper has been closing
            this long with the object's estimate not between the fingers, the closed hand rises where it is to the
            band's top before it goes on (``mmact_ctrl.control.empty_hand``), s; None: no such gate.
        empty_hand_beside_m: with the empty-hand gate and ``capture_tol_m``: the gate also acts as soon as the
            fingers' measured opening can no longer take in the object and the object's estimate is off the TCP
            across the fingers' axis by more than this (beside the fingers: ``EmptyHandGate.missed_on_opening``), not
            only after ``empty_hand_after_s``, m; None: only after it. Without a measured opening nothing changes.
        empty_grip_below_m: with a descent band, in a mode that does not read the object: fingers commanded closed
            and measured closer than this found nothing, and the hand rises to the band's top at once
            (``mmact_ctrl.control.empty_grip``), m; None: no such gate.
        target_box_m: (low, high) corners of the box the target's carrier keeps it in (a contact task's conveyor or
            fixture rail), m; the fast layer's predictions are reflected at its walls, as the task's chunk source's
            lead is (``controllers.estimation.box``). None (reach): unbounded, as published.
        grasp_reflex: the fast layer closes the gripper when the measured object is between the fingers, and keeps
            it open until then, whatever the chunk's clock says (``mmact_ctrl.control.grasp_reflex``).
        compliance: the TCP tracks its reference as a spring-damper, stiff or soft per tool axis, whose force is
            capped below ``contact_force_limit_n`` (``controllers.qp.impedance``), in place of stiff tracking.
        compliance_caps_pressing: with ``compliance``, the cap acts only on the force's push into the measured
            contact (``ImpedanceTask.pressing_only``): the force that lifts the hand off the contact, or moves it
            along it, is not capped. False (insert): the force's magnitude is capped, as published.
        close_below_m: the gripper starts closing only with the TCP below this height, m, in every mode
            (``mmact_ctrl.control.closing_gate``); None (reach, insert): the chunk's clock decides.
        close_below_reading_m: with ``close_below_m``, in a mode that reads the object: the gripper starts closing
            only with the TCP below this height instead (pick with ``--close-at-grasp``: its grasp height), m; None:
            ``close_below_m``.
        close_stops_descent_m: with ``close_below_reading_m``, in a mode that reads the object: once the gripper
            starts closing, the reference does not go lower than the TCP's height then less this, m, while the
            gripper is commanded closed (a pad that slides down an object's side wedges it against what it rests on;
            README, Contact, point 14); None: the descent goes on.
        descent_band_m: (low, high) TCP heights, m, that the reference passes going down at most at
            ``descent_speed_m_s`` in a mode that reads the object, and with it the TCP floor as a braking curve in
            every mode (``mmact_ctrl.control.descent``); None (reach, insert): no such stage.
        descent_speed_m_s: that speed, m/s.
        landing_speed_m_s: with a descent band, in a mode that does not read the object: the band's speed there, m/s
            (the hand cannot know whether something is under it, so it passes the objects' top no faster than a
            landing stays under the contact-force limit: ``scenarios.landing_floor``); None: no band in those modes.
        capture_tol_m: with a descent band, in a mode that reads the object: the hand stays over the band while the
            object's estimate is off the fingers' axis by more than this, m (``mmact_ctrl.control.capture_gate``);
            None: no such gate.
        capture_clear_m: the gate's width across the fingers' axis: an object off the TCP by more than this across it
            clears the fingers, m.
    """

    mode: str = "hybrid"
    use_ruckig: bool = True
    use_mpc: bool = True
    retarget: RetargetConfig = field(default_factory=RetargetConfig)
    replan_hz: float = 1.0
    latency_ms: float = 200.0
    measured_latency: bool = False
    bins: int = 2048
    dt_s: float = 0.001
    perception_hz: float = 100.0
    duration_s: float = 6.0
    receding_k: int = 0
    ensemble_decay_per_s: float = 1.0
    chunk_timeout_s: float = 2.5
    splice_radius_m: float = 0.1
    tcp_floor_m: float = 0.05
    mpc_plan_start: str = "measured"
    plan_resync_m: float = 0.02
    plan_resync_m_s: float = 0.25
    abort_after_missed_ticks: int = 20
    mpc_keep_plan_s: float = 0.1
    mpc_blend_s: float = 0.02
    mpc_phase_s: float = 0.0
    mpc_delay_s: float | None = None
    mpc_preview_governed: bool = True
    latch_on_grip: bool = True
    residual_checkpoint: str = ""
    contact_force_limit_n: float = 30.0
    guard_yield_m_s_per_n: float = YIELD_M_S_PER_N
    empty_hand_after_s: float | None = None
    empty_hand_beside_m: float | None = None
    empty_grip_below_m: float | None = None
    grasp_reflex: bool = False
    compliance: bool = False
    compliance_caps_pressing: bool = False
    close_below_m: float | None = None
    close_below_reading_m: float | None = None
    close_stops_descent_m: float | None = None
    descent_band_m: tuple[float, float] | None = None
    descent_speed_m_s: float = 0.05
    landing_speed_m_s: float | None = None
    capture_tol_m: float | None = None
    capture_clear_m: float = 0.037
    target_box_m: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    qp: QPConfig = field(default_factory=QPConfig)
    smoother: SmootherConfig = field(default_factory=SmootherConfig)
    filter: EstimatorConfig = field(default_factory=EstimatorConfig)
    mpc: MPCConfig = field(default_factory=MPCConfig)

    def __post_init__(self) -> None:
        check_mode(self.mode)
        if not self.replan_hz > 0:
            raise ValueError(f"replan_hz must be > 0, got {self.replan_hz}")
        if not self.latency_ms >= 0:
            raise ValueError(f"latency_ms must be >= 0, got {self.latency_ms}")
        if not isinstance(self.bins, int) or self.bins < 0 or self.bins == 1:
            raise ValueError(f"bins must be 0 (no quantization) or an int >= 2, got {self.bins!r}")
        if not self.dt_s > 0:
            raise ValueError(f"dt_s must be > 0, got {self.dt_s}")
        if not self.perception_hz > 0 or self.perception_hz > 1.0 / self.dt_s + 1e-9:
            raise ValueError(f"perception_hz must be in (0, {1.0 / self.dt_s:g}], got {self.perception_hz}")
        if not self.duration_s > 0:
            raise ValueError(f"duration_s must be > 0, got {self.duration_s}")
        if self.target_box_m is not None:
            low, high = (np.asarray(c, dtype=float) for c in self.target_box_m)
            if low.shape != (3,) or high.shape != (3,) or not np.all(np.isfinite(low)) or not np.all(high > low):
                raise ValueError(f"target_box_m must be (low, high) with 3 finite numbers each and high > low, got "
                                 f"{self.target_box_m!r}")
        if self.receding_k < 0:
            raise ValueError(f"receding_k must be >= 0, got {self.receding_k}")
        if not self.ensemble_decay_per_s >= 0:
            raise ValueError(f"ensemble_decay_per_s must be >= 0, got {self.ensemble_decay_per_s}")
        if not (self.chunk_timeout_s > 0 and math.isfinite(self.chunk_timeout_s)):
            raise ValueError(f"chunk_timeout_s must be a finite number > 0, got {self.chunk_timeout_s}")
        if not self.splice_radius_m > 0:
            raise ValueError(f"splice_radius_m must be > 0, got {self.splice_radius_m}")
        if not (math.isfinite(self.contact_force_limit_n) and self.contact_force_limit_n > 0):
            raise ValueError(f"contact_force_limit_n must be a force > 0 N, got {self.contact_force_limit_n}")
        if not (math.isfinite(self.guard_yield_m_s_per_n) and self.guard_yield_m_s_per_n > 0):
            raise ValueError(f"guard_yield_m_s_per_n must be a rate > 0 m/s/N, got {self.guard_yield_m_s_per_n}")
        if self.empty_hand_after_s is not None and not (math.isfinite(self.empty_hand_after_s)
                                                        and self.empty_hand_after_s > 0):
            raise ValueError(f"empty_hand_after_s must be a time > 0 s or None, got {self.empty_hand_after_s}")
        if self.empty_hand_beside_m is not None and not (math.isfinite(self.empty_hand_beside_m)
                                                         and self.empty_hand_beside_m > 0):
            raise ValueError(f"empty_hand_beside_m must be a distance > 0 m or None, got {self.empty_hand_beside_m}")
        if self.close_below_m is not None and not math.isfinite(self.close_below_m):
            raise ValueError(f"close_below_m must be a finite height in m or None, got {self.close_below_m}")
        if self.close_below_reading_m is not None and not math.isfinite(self.close_below_reading_m):
            raise ValueError(f"close_below_reading_m must be a finite height in m or None, got "
                             f"{self.close_below_reading_m}")
        if self.close_stops_descent_m is not None and not (math.isfinite(self.close_stops_descent_m)
                                                           and self.close_stops_descent_m >= 0):
            raise ValueError(f"close_stops_descent_m must be a distance >= 0 m or None, got "
                             f"{self.close_stops_descent_m}")
        if self.close_stops_descent_m is not None and self.close_below_reading_m is None:
            raise ValueError(f"close_stops_descent_m ({self.close_stops_descent_m}) acts only with "
                             f"close_below_reading_m (the closing from the grasp height); got close_below_reading_m None")
        if self.descent_band_m is not None:
            low, high = (float(z) for z in self.descent_band_m)
            if not (math.isfinite(low) and math.isfinite(high) and high > low >= self.tcp_floor_m):
                raise ValueError(f"descent_band_m must be (low, high) heights in m with high > low >= tcp_floor_m, "
                                 f"got {self.descent_band_m!r}")
        if self.capture_tol_m is not None and not (math.isfinite(self.capture_tol_m) and self.capture_tol_m > 0):
            raise ValueError(f"capture_tol_m must be a distance > 0 in m or None, got {self.capture_tol_m}")
        if not (math.isfinite(self.capture_clear_m) and self.capture_clear_m >= 0):
            raise ValueError(f"capture_clear_m must be a distance >= 0 in m, got {self.capture_clear_m}")
        if not (math.isfinite(self.descent_speed_m_s) and self.descent_speed_m_s > 0):
            raise ValueError(f"descent_speed_m_s must be a speed > 0 m/s, got {self.descent_speed_m_s}")
        if self.empty_grip_below_m is not None and not (math.isfinite(self.empty_grip_below_m)
                                                        and self.empty_grip_below_m > 0):
            raise ValueError(f"empty_grip_below_m must be an opening > 0 m or None, got {self.empty_grip_below_m}")
        if self.landing_speed_m_s is not None and not (math.isfinite(self.landing_speed_m_s)
                                                       and self.landing_speed_m_s > 0):
            raise ValueError(f"landing_speed_m_s must be a speed > 0 m/s or None, got {self.landing_speed_m_s}")
        if not math.isfinite(self.tcp_floor_m):
            raise ValueError(f"tcp_floor_m must be a finite height in m, got {self.tcp_floor_m}")
        if self.mpc_plan_start not in ("measured", "tracked"):
            raise ValueError(f"mpc_plan_start must be 'measured' or 'tracked', got {self.mpc_plan_start!r}")
        if not (self.plan_resync_m > 0 and self.plan_resync_m_s > 0):
            raise ValueError(f"plan_resync_m and plan_resync_m_s must be > 0, got {self.plan_resync_m}, "
                             f"{self.plan_resync_m_s}")
        if not 0 < self.mpc_keep_plan_s <= self.mpc.horizon_steps * self.mpc.dt_s:
            raise ValueError(f"mpc_keep_plan_s must be in (0, the MPC horizon {self.mpc.horizon_steps * self.mpc.dt_s:g} s], "
                             f"got {self.mpc_keep_plan_s}")
        if not 0 <= self.mpc_blend_s <= self.mpc.horizon_steps * self.mpc.dt_s:
            raise ValueError(f"mpc_blend_s must be in [0, the MPC horizon], got {self.mpc_blend_s}")
        if not 0 <= self.mpc_phase_s < 1.0 / self.mpc.rate_hz:
            raise ValueError(f"mpc_phase_s must be in [0, the MPC period {1.0 / self.mpc.rate_hz:g} s), got {self.mpc_phase_s}")
        if self.mpc_delay_s is not None and not 0 <= self.mpc_delay_s <= 1.0 / self.mpc.rate_hz:
            raise ValueError(f"mpc_delay_s must be None or in [0, the MPC period {1.0 / self.mpc.rate_hz:g} s], "
                             f"got {self.mpc_delay_s}")
        if self.abort_after_missed_ticks < 1:
            raise ValueError(f"abort_after_missed_ticks must be >= 1, got {self.abort_after_missed_ticks}")
        if self.latency_ms / 1000.0 >= self.duration_s:
            raise ValueError(
                f"latency_ms={self.latency_ms:g} is not shorter than the episode ({self.duration_s:g} s): no chunk would ever run"
            )
