"""The 1 kHz control layer under the chunk source, as a chain of stages (``mmact_ctrl.control``):

    executed chunk (+ the executor's correction)  ChunkStage     -> ReferenceSample
    raised to the TCP floor                       FloorClamp     -> ReferenceSample
    Ruckig                                        SmoothingStage -> SmoothedSample
    the MPC plan, blended; or the bypass          PlanTracker    -> TrackedReference   (with the MPC)
    the task-space inverse-dynamics QP            TaskSpaceQP    -> torques            (controllers.qp)

The executor of the episode (``mmact_ctrl.executors``, one per ``StackConfig.mode``) gives the reference and says
which layers run under it; each ``StackConfig`` switch turns a layer off. This class knows no mode names.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from controllers.estimation.box import BoxedPrediction
from controllers.mpc import TaskSpaceMPC
from controllers.qp import TaskReference, TaskSpaceQP
from controllers.qp.impedance import ImpedanceTask
from controllers.robot_model import PandaModel, RobotTerms
from controllers.rotations import rotvec_from_rot
from controllers.smoother import TaskSpaceSmoother
from controllers.target_estimator import TargetEstimator
from mmact_ctrl.chunk import ActionChunk
from mmact_ctrl.config import StackConfig
from mmact_ctrl.control.chunk_stage import GRIPPER_OPEN_M, ChunkStage
from mmact_ctrl.control.capture_gate import CaptureGate
from mmact_ctrl.control.closing_gate import ClosingGate
from mmact_ctrl.control.compliance_gate import ComplianceGate
from mmact_ctrl.control.descent import DescentGovernor
from mmact_ctrl.control.empty_grip import EmptyGripGate
from mmact_ctrl.control.empty_hand import EmptyHandGate
from mmact_ctrl.control.fingers import FingerWatch
from mmact_ctrl.control.floor import FloorClamp
from mmact_ctrl.control.force_guard import ContactForceGuard
from mmact_ctrl.control.grasp_reflex import CLOSING_BELOW_M, GraspReflex, reflex_refusal
from mmact_ctrl.control.plan_tracker import PlanTracker
from mmact_ctrl.control.samples import ControllerCounters, ReferenceSample, SmoothedSample, TickOutput
from mmact_ctrl.control.smoothing import SmoothingStage
from mmact_ctrl.control.view import ExecutorView
from mmact_ctrl.executors import ChunkExecutor, make_executor
from mmact_ctrl.mpc_worker import DeferredMPC, InlineMPC
from mmact_ctrl.reference import ChunkReference

#: a measured external force over this at the TCP is contact: the chunk's correction is latched (ChunkStage), N (a held
#: 50 g peg weighs 0.5 N; a touch on a fixture is several N)
CONTACT_LATCH_N = 3.0


def make_qp(config: StackConfig) -> TaskSpaceQP:
    """The 1 kHz QP: the default tasks (the compiled fast path), and with ``config.compliance`` the impedance task
    that takes the stiff TCP position task's place while the robot is in contact (``controllers.qp.impedance``; its
    force capped at 2/3 of the contact-force limit, so that the spring and the damper together stay under it; the
    controller's :class:`ComplianceGate` says when)."""
    qp_config = replace(config.qp, dt_s=config.dt_s)
    if not config.compliance:
        return TaskSpaceQP(qp_config)
    return TaskSpaceQP(qp_config, contact_task=ImpedanceTask(force_max_n=config.contact_force_limit_n * 2.0 / 3.0,
                                                             pressing_only=config.compliance_caps_pressing))


class HybridController:
    """Executes chunks at the control rate (see the module).

    Args:
        config: the stack's configuration.
        model: the robot model (None: the Panda's).
        executor: how chunks are executed (None: the built-in executor named ``config.mode``); any object that
            satisfies ``mmact_ctrl.executors.ChunkExecutor``.
    """

    def __init__(self, config: StackConfig, model: PandaModel | None = None,
                 executor: ChunkExecutor | None = None) -> None:
        self.config = config
        self.model = model if model is not None else PandaModel()
        self.qp = make_qp(config)
        self.executor = executor if executor is not None else make_executor(config.mode)
        layers = self.executor.layers
        if config.grasp_reflex and not layers.reads_target:
            raise ValueError(reflex_refusal(config.mode))
        self.reads_target = layers.reads_target
        self.smoothing = layers.smooth and config.use_ruckig
        self.use_mpc = layers.preview and config.use_mpc
        self.q_post = self.model.home_q_rad
        _, self.rot_nominal = self.model.fk(self.q_post)
        self.filter = TargetEstimator(replace(config.filter, dt_s=1.0 / config.perception_hz))
        self.estimate = self._estimate_view()
        sc = config.smoother
        self.chunk = ChunkStage(self.executor, (sc.a_max_m_s2, sc.j_max_m_s3, sc.dw_max_rad_s2, sc.ddw_max_rad_s3),
                                in_hand=self._object_in_hand)
        self._force_n = 0.0  # the measured external force at the TCP (sense_wrench), N
        self._normal = np.zeros(3)  # its direction, unit (sense_wrench; the compliant QP's cap acts along it)
        self.force_guard = ContactForceGuard(config.contact_force_limit_n, config.dt_s, config.tcp_floor_m,
                                             config.guard_yield_m_s_per_n)
        #: ``--compliance``: the impedance in contact, stiff tracking in free space (None: stiff throughout)
        self.compliance = ComplianceGate(CONTACT_LATCH_N, config.dt_s) if config.compliance else None
        self.floor = FloorClamp(config.tcp_floor_m)
        self.reflex = GraspReflex(config.grasp_reflex)
        self.closing_gate = self._closing_gate(config, layers.reads_target)
        self.descent = None if config.descent_band_m is None else self._descent_governor(config, layers.reads_target)
        self.capture = (CaptureGate(config.capture_tol_m, config.capture_clear_m, config.descent_band_m[1], config.dt_s)
                        if config.capture_tol_m is not None and config.descent_band_m is not None
                        and layers.reads_target else None)  # the hand over the object's top until it is between
        self.empty_hand = (EmptyHandGate(config.empty_hand_after_s, config.descent_band_m[1], config.dt_s,
                                         opening_tol_m=(config.capture_tol_m if config.empty_hand_beside_m is not None
                                                        else None),
                                         beside_m=config.empty_hand_beside_m or 0.0)
                           if config.empty_hand_after_s is not None and config.descent_band_m is not None
                           and config.close_below_m is not None and layers.reads_target else None)
        self.empty_grip = (EmptyGripGate(config.empty_grip_below_m, config.descent_band_m[1], config.dt_s)
                           if config.empty_grip_below_m is not None and config.descent_band_m is not None
                           and config.close_below_m is not None and not layers.reads_target else None)
        #: the fingers' measured opening (sense_wrench; ``opening_m``, m) and whether they still close on nothing
        self.fingers = FingerWatch(config.dt_s)
        # With MPC, Ruckig steps once per MPC period (its output is only read there); else every control tick.
        self.smoother = TaskSpaceSmoother(replace(sc, dt_s=1.0 / config.mpc.rate_hz if self.use_mpc else config.dt_s))
        self.smooth = SmoothingStage(self.smoother if self.smoothing else None, self.floor, self.rot_nominal)
        self.tracker = self._plan_tracker() if self.use_mpc else None
        self.terms: RobotTerms | None = None
        self._gripper_m = GRIPPER_OPEN_M
        self.executor.bind(ExecutorView(self))
        self._warm_up_qp()

    @staticmethod
    def _closing_gate(config: StackConfig, reads_target: bool) -> ClosingGate:
        """The closing gate: with ``StackConfig.close_below_reading_m`` (pick's ``--close-at-grasp``: its grasp height)
        and where the hand reads the object, from that height, the descent stopping there
        (``close_stops_descent_m``; README, Contact, point 14); otherwise from ``close_below_m``, the descent going
        on (None: the chunk's clock decides)."""
        if config.close_below_m is None:
            return ClosingGate(None, config.dt_s)
        if reads_target and config.close_below_reading_m is not None:
            return ClosingGate(config.close_below_reading_m, config.dt_s, config.close_stops_descent_m)
        return ClosingGate(config.close_below_m, config.dt_s)

    @staticmethod
    def _descent_governor(config: StackConfig, reads_target: bool) -> DescentGovernor:
        """The guarded descent: the band at the guarded move's speed where the hand follows the object; where it
        cannot, at the landing speed (``StackConfig.landing_speed_m_s``; None: the floor's braking curve only), the
        reference held near the measured TCP."""
        if reads_target:
            band, speed = config.descent_band_m, config.descent_speed_m_s
        elif config.landing_speed_m_s is not None:
            band, speed = config.descent_band_m, config.landing_speed_m_s
        else:
            band, speed = None, config.descent_speed_m_s
        return DescentGovernor(band, speed, config.tcp_floor_m, config.dt_s, follow_tcp=not reads_target)

    def _plan_tracker(self) -> PlanTracker:
        # the MPC object never discards a slow solve itself: lateness is the worker's to judge (in real time, a plan
        # that arrives later than config.mpc.max_solve_ms; in simulated time none: results must not depend on load)
        mpc = self._mpc = TaskSpaceMPC(replace(self.config.mpc, max_solve_ms=math.inf), q_nominal_rad=self.model.home_q_rad)
        relative = self.smoothing and self.config.smoother.relative
        delay = self.config.mpc_delay_s
        worker = (InlineMPC(mpc) if delay is None  # the published results: solved at the tick that asks
                  else DeferredMPC(replace(self.config.mpc, max_solve_ms=math.inf), self.model.home_q_rad, delay))
        return PlanTracker(self.config, self.model, worker, self.smoothed_reference, self.reference_positions,
                           self.smoother.preview_pos_offset if relative else None,
                           self.descent.lowest_z_m if self.descent is not None and self.config.mpc_preview_governed
                           else None)

    def _warm_up_qp(self) -> None:
        """The QP's rare paths (DAQP's rescue, the fallback) run once now, not for the first time inside an episode."""
        zeros7 = np.zeros(7)
        home = self.model.terms(self.q_post, zeros7)
        self.qp.warm_up(home, self.q_post, zeros7, TaskReference(np.array(home.pos_m), np.zeros(3), np.zeros(3),
                                                                 np.array(home.rot), np.zeros(3), np.zeros(3), self.q_post))

    # ---- what others read ------------------------------------------------------------------------------------
    @property
    def mode(self) -> str:
        """The executor's name (``StackConfig.mode`` unless an executor was given)."""
        return self.executor.name

    @property
    def active(self) -> ChunkReference | None:
        """The executed chunk (None before the first)."""
        return self.chunk.active

    @property
    def stop(self):
        """The watchdog's braking stop under way, or None."""
        return self.chunk.stop

    @property
    def mpc(self) -> TaskSpaceMPC | None:
        """The MPC (None without it); its worker solves it (``mpc_worker``)."""
        return self._mpc if self.tracker is not None else None

    @property
    def mpc_worker(self):
        return self.tracker.worker if self.tracker is not None else None

    @property
    def recorded_plans(self) -> list | None:
        return self.tracker.recorded_plans if self.tracker is not None else None

    @recorded_plans.setter
    def recorded_plans(self, plans: list | None) -> None:
        if self.tracker is not None:
            self.tracker.recorded_plans = plans

    @property
    def offpath_us(self) -> float:
        """This tick's time on work real time does beside the command path (MPC update + solve), us."""
        return self.tracker.offpath_us if self.tracker is not None else 0.0

    @property
    def after_us(self) -> float:
        """The part of :attr:`offpath_us` real time does on the loop's thread after the command (the update), us."""
        return self.tracker.after_us if self.tracker is not None else 0.0

    @property
    def last_torque_nm(self) -> np.ndarray | None:
        """The last torque the robot received (the QP's ``tau_last``)."""
        return self.qp.tau_last

    def counters(self) -> ControllerCounters:
        """What the controller survived this episode."""
        worker, tr = self.mpc_worker, self.tracker
        return ControllerCounters(
            watchdog_stops=self.chunk.watchdog_stops, floor_clamps=self.floor.clamps,
            plan_resyncs=tr.plan_resyncs if tr is not None else 0, mpc_bypass_ticks=tr.bypass_ticks if tr is not None else 0,
            qp_failures=self.qp.failures, qp_rescues=self.qp.rescues, rate_clamps=self.qp.rate_clamps,
            smoother_failures=self.smoother.failures,
            mpc_failures=int(worker.failures + worker.late) if worker is not None else 0,
            mpc_solve_us=tuple(getattr(worker, "solve_us", ())) if worker is not None else (),
            gated_measurements={"nonfinite": self.filter.gated_nonfinite, "frozen": self.filter.gated_frozen,
                                "outlier": self.filter.gated_outlier})

    def use_mpc_worker(self, worker) -> None:
        """Solve the MPC with ``worker`` (``mmact_ctrl.mpc_worker``: :class:`ProcessMPC` in real time) instead of
        inline; the previous worker is closed."""
        if self.tracker is not None:
            self.tracker.use_worker(worker)

    def close(self) -> None:
        """End the MPC's process, if it has one (``StackConfig.mpc_delay_s``); from then on the MPC is solved inline.
        Safe to call twice."""
        if self.tracker is not None and not isinstance(self.tracker.worker, InlineMPC):
            self.tracker.use_worker(InlineMPC(self._mpc))

    def defer_mpc_updates(self, defer: bool) -> None:
        """The deadline order (``mmact_ctrl.tick_order``): the MPC's work after each command (:meth:`end_tick`)."""
        if self.tracker is not None:
            self.tracker.defer_updates = bool(defer)

    # ---- the episode -------------------------------------------------------------------------------------------
    def reset(self, q_rad: np.ndarray, dq_rad_s: np.ndarray | None = None,
              gripper_m: float = GRIPPER_OPEN_M) -> np.ndarray:
        """New episode: hold the current pose and the gripper's opening ``gripper_m`` (m) until the first chunk is
        active. Returns the torque the robot is
        taken to apply before the first command, ``h(q, dq)`` (gravity, Coriolis, damping: what a Panda's own
        gravity compensation does with a zero user torque); the first command's rate is measured against it."""
        q = np.asarray(q_rad, dtype=float)
        dq = np.zeros(7) if dq_rad_s is None else np.asarray(dq_rad_s, dtype=float)
        pos, rot = self.model.fk(q)
        rotvec = rotvec_from_rot(rot, self.rot_nominal)
        self._gripper_m = float(gripper_m)
        self._force_n = 0.0
        self.chunk.touching = False
        self.force_guard.reset()
        if self.compliance is not None:
            self.compliance.reset()  # and the QP's reset below puts it in free space
        self.chunk.reset(pos, rotvec, gripper_m)
        self.floor.clamps = 0
        self.reflex.reset()
        self.closing_gate.reset()
        if self.descent is not None:
            self.descent.reset()
        if self.capture is not None:
            self.capture.reset()
        if self.empty_hand is not None:
            self.empty_hand.reset()
        if self.empty_grip is not None:
            self.empty_grip.reset()
        self.fingers.reset()
        self.smoother.reset(pos, rotvec)
        self.smooth.smoothed_pos_m = None
        self.filter = TargetEstimator(self.filter.config)
        self.estimate = self._estimate_view()
        tau_start = np.array(self.model.terms(q, dq).h)
        self.qp.reset(tau_start)
        if self.tracker is not None:
            self.tracker.reset(pos, rot)
        self.terms = None
        self.executor.reset()
        return tau_start

    def ee_pose(self, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """TCP position (m) and rotation vector relative to the nominal grasp (rad) at ``q``."""
        pos, rot = self.model.fk(q_rad)
        return pos, rotvec_from_rot(rot, self.rot_nominal)

    # ---- inputs at their own rates -----------------------------------------------------------------------------
    def perceive(self, t_capture_s: float, z_m: np.ndarray | None) -> None:
        """Fuse one target measurement of the scene as it was at ``t_capture_s`` (None = missed); it may arrive
        later than that (sensor latency): the filter fuses it at its capture time and predicts to now."""
        if self.reads_target:
            self.filter.fuse(t_capture_s, z_m)
            self.executor.perceive(t_capture_s, z_m)

    def target_estimate(self, t_s: float) -> np.ndarray | None:
        """The filtered target estimate predicted to ``t_s`` (None before the first measurement)."""
        return self.filter.predict_pos(t_s) if self.filter.initialized else None

    def activate(self, chunk: ActionChunk, t_s: float, target_at_obs_m: np.ndarray | None) -> None:
        """Make ``chunk`` the active chunk at ``t_s`` (its observation time + latency); ends a watchdog stop."""
        target_at_obs_m = self._target_at_observation(chunk.t0_s, target_at_obs_m)
        self.chunk.activate(ChunkReference(chunk=chunk, t_active_s=t_s, target_at_obs_m=target_at_obs_m), t_s)

    def splice_distance_m(self, chunk: ActionChunk, t_s: float, target_at_obs_m: np.ndarray | None,
                          ee_at_obs_m: np.ndarray | None = None) -> float:
        """How far the reference would jump at ``t_s`` if ``chunk`` became active now, m: the distance from where it
        would start (the executor's correction included, :meth:`start_position`) to the nearest of what the robot is
        following or doing now: the raw reference, the Ruckig-smoothed one (any jump of the raw reference is absorbed
        and smoothed away, so a start near either is no jump) and the TCP itself (a chunk that starts where the arm
        is asks for no jump of the arm); or, given ``ee_at_obs_m``, the distance from the chunk's first waypoint to the
        TCP it was planned from (a plan of the robot's own motion, however late it arrives; a corrupted chunk begins
        elsewhere), whichever is smallest."""
        start = self.start_position(chunk, t_s, target_at_obs_m)
        gap = float(np.linalg.norm(start - self.reference(t_s).pos_m))
        if self.smoothing and self.smooth.smoothed_pos_m is not None:
            gap = min(gap, float(np.linalg.norm(start - self.smooth.smoothed_pos_m)))
        if self.terms is not None:
            gap = min(gap, float(np.linalg.norm(start - self.terms.pos_m)))
        if ee_at_obs_m is not None:
            gap = min(gap, float(np.linalg.norm(chunk.waypoints[0, :3] - np.asarray(ee_at_obs_m, dtype=float))))
        return gap

    def _target_at_observation(self, t0_s: float, recorded_m: np.ndarray | None) -> np.ndarray | None:
        """Where the target was at the chunk's observation time, as best known now: the filter's estimate from the
        measurements captured up to ``t0_s`` (``filtered_at``), else the one recorded then, else the current estimate
        extrapolated back; then corrected for a jump the observation already saw (``estimate_at_observation``)."""
        best = self.filter.filtered_at(t0_s) if self.filter.initialized else None
        if best is None:
            best = recorded_m if recorded_m is not None else (self.filter.predict_pos(t0_s) if self.filter.initialized else None)
        return self.filter.estimate_at_observation(t0_s, best)

    def start_position(self, chunk: ActionChunk, t_s: float, target_at_obs_m: np.ndarray | None) -> np.ndarray:
        """The position (3,) m the reference would take at ``t_s`` if ``chunk`` became active now, the executor's
        correction included (what the splice check compares with the reference being executed)."""
        target_at_obs_m = self._target_at_observation(chunk.t0_s, target_at_obs_m)
        ref = ChunkReference(chunk=chunk, t_active_s=t_s, target_at_obs_m=target_at_obs_m)
        return ref.sample(t_s)[0][:3] + self.executor.offset(t_s, ref)[0]

    # ---- the stale-chunk watchdog --------------------------------------------------------------------------------
    def covered(self, t_s: float) -> bool:
        """Whether a chunk (or, before the first one, the initial hold) covers ``t_s``."""
        return self.chunk.covered(t_s)

    def watchdog(self, t_s: float) -> bool:
        """No valid chunk covers ``t_s``: brake the reference to rest from where it is now, within the smoother's
        acceleration and jerk limits, and hold there until a new chunk is activated. Returns whether a stop
        started now (counted in ``watchdog_stops``); a stop already under way goes on."""
        return self.chunk.brake(t_s, self.reference(t_s)) if self.chunk.stop is None else False

    @property
    def watchdog_stops(self) -> int:
        return self.chunk.watchdog_stops

    # ---- the reference chain ---------------------------------------------------------------------------------------
    def reference(self, t_s: float) -> ReferenceSample:
        """The reference before smoothing: the executed chunk's (:class:`ChunkStage`), raised to the TCP floor."""
        return self.floor(self.chunk.sample(t_s))

    def reference_positions(self, times_s: np.ndarray) -> np.ndarray:
        """Positions (N, 3) of :meth:`reference` at many times at once (the MPC's preview), vectorized."""
        return self.floor.positions(self.chunk.positions(np.asarray(times_s, dtype=float)))

    def smoothed_reference(self, t_s: float) -> SmoothedSample:
        """The reference after Ruckig (advances the smoother)."""
        return self.smooth(self.reference(t_s))

    # ---- the 1 kHz tick --------------------------------------------------------------------------------------------
    def tick(self, t_s: float, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> TickOutput:
        """One control period: torques for the measured joint state, one stage a line. Without the MPC the reference
        is smoothed every tick; with it the QP tracks the plan, and the reference is smoothed at the MPC's rate (its
        output is only read there; see :class:`PlanTracker` for the plan's hand-over and bypass)."""
        terms = self.terms = self.model.terms(q_rad, dq_rad_s)
        if self.tracker is not None:
            tracked = self.tracker.track(t_s, q_rad, dq_rad_s, terms)
            s, pos, vel, acc, q_post = tracked.smoothed, tracked.pos_m, tracked.vel_m_s, tracked.acc_m_s2, tracked.q_post_rad
        else:
            s = self.smoothed_reference(t_s)
            pos, vel, acc, q_post = s.pos_m, s.vel_m_s, s.acc_m_s2, self.q_post
        obj = (self._object_now(t_s) if self.reflex.enabled or self.capture is not None or self.empty_hand is not None
               else None)  # once a tick
        gripper_m = self.reflex(s.gripper_m, terms.pos_m, obj) if self.reflex.enabled else s.gripper_m
        if self.closing_gate.close_below_m is not None:  # not before the hand is down, no lift while closing
            gripper_m = self.closing_gate(gripper_m, float(terms.pos_m[2]))
            pos, vel, acc = self.closing_gate.hold(pos, vel, acc)
        if self.capture is not None:  # not down past the object's top unless it will pass between the fingers
            pos, vel, acc = self.capture(pos, vel, acc, terms.pos_m, terms.rot, obj)
        if self.empty_hand is not None:  # a closing that found nothing: up before sideways
            closing = self.closing_gate.closing_ticks
            rel_vel = (self.filter.predict_vel(t_s) - terms.vel[:3]  # only while the fingers close on something
                       if closing > 0 and obj is not None and self.empty_hand.opening_tol_m is not None else None)
            pos, vel, acc = self.empty_hand(pos, vel, acc, terms.pos_m, obj, closing, terms.rot,
                                            self.fingers.opening_m, rel_vel)
        if self.empty_grip is not None:  # blind: fingers that closed on nothing lift the hand at once
            pos, vel, acc = self.empty_grip(pos, vel, acc, float(terms.pos_m[2]), self.fingers.opening_m,
                                            self.closing_gate.closing_ticks)
        if self.force_guard.active:  # pressing on something (``ContactForceGuard``): the reference yields
            pos = self.force_guard.apply(pos)
            if self.descent is not None:  # a guarded move also stops going on into the contact
                vel, acc = self.force_guard.halt(vel, acc)
        if self.descent is not None:  # a guarded move past the objects' top, the floor as a braking curve
            pos, vel, acc = self.descent(pos, vel, acc, float(terms.pos_m[2]), float(terms.vel[2]),
                                         self.chunk.touching)
        tau = self.qp.solve(terms, q_rad, dq_rad_s,
                            TaskReference(pos, vel, acc, s.rot, s.ang_vel_rad_s, s.ang_acc_rad_s2, q_post))
        self._gripper_m = gripper_m
        return TickOutput(tau_nm=tau, gripper_m=gripper_m, ref_pos_m=s.pos_m, ee_pos_m=terms.pos_m,
                          ddq_cmd_rad_s2=self.qp.last_ddq, tcp_vel_m_s=terms.vel[:3])

    def sense_wrench(self, wrench: np.ndarray, gripper_m: float | None = None) -> None:
        """The robot's measured external wrench at the TCP this tick (``RobotState.wrench_ext``; the runner calls it
        only where the world measures one: in reach nothing of this runs), and the fingers' measured opening
        ``gripper_m`` (m; None: not given). Contact (the force over ``CONTACT_LATCH_N``) latches the chunk's
        correction; the guard sees the force; the empty-grip gate the opening."""
        self.fingers.update(gripper_m)
        force = np.asarray(wrench, dtype=float)[:3]
        self._force_n = float(np.linalg.norm(force))
        self.chunk.touching = self._force_n > CONTACT_LATCH_N
        self.force_guard.update(force)
        if self.compliance is not None:  # the impedance's turn in the QP, or the stiff position task's
            normal = np.divide(force, self._force_n, out=self._normal) if self._force_n > 0.0 else None  # no allocation
            self.qp.set_contact(self.compliance.update(self._force_n), normal)

    def _estimate_view(self):
        """What the executors read of the target estimate: the estimator, or its predictions reflected at the walls of
        ``config.target_box_m`` (``controllers.estimation.box``)."""
        box = self.config.target_box_m
        return self.filter if box is None else BoxedPrediction(self.filter, box[0], box[1])

    def _object_in_hand(self) -> bool:
        """Whether the target estimate is between the fingers at the last tick's TCP (``GraspReflex.between``), or,
        with fingers that measure something in them (wider than ``config.empty_grip_below_m``: closed on an object, not
        on nothing), still in their grip (``GraspReflex.holding``). With ``config.latch_on_grip``, never while the
        fingers are measured wide open or still closing freely (``FingerWatch``: nothing is held yet)."""
        terms = getattr(self, "terms", None)
        if terms is None or not self.filter.initialized:
            return False
        if self.config.latch_on_grip and self.fingers.on_nothing_yet:  # not held yet: the object moves with the world
            return False
        obj = self.filter.predict_pos(self.filter.t_s)
        if GraspReflex.between(terms.pos_m, obj):
            return True
        empty, opening = self.config.empty_grip_below_m, self.fingers.opening_m
        return (empty is not None and opening is not None and empty < opening < CLOSING_BELOW_M
                and GraspReflex.holding(terms.pos_m, obj))

    def _object_now(self, t_s: float) -> np.ndarray | None:
        """The target estimate now (the grasp reflex's object), None before the first measurement."""
        return self.filter.predict_pos(t_s) if self.filter.initialized else None

    def end_tick(self, spare: bool = True) -> float:
        """After the tick's command is sent (the deadline order): a stage of the deferred MPC update
        (:meth:`PlanTracker.after_command`). Returns the time it took, us."""
        return self.tracker.after_command(spare) if self.tracker is not None else 0.0

    # ---- commands that do not arrive --------------------------------------------------------------------------------
    def command_state(self) -> tuple[np.ndarray | None, np.ndarray]:
        """(last torque sent, last commanded acceleration): what a command that comes too late leaves standing."""
        tau = self.qp.tau_last
        return (None if tau is None else tau.copy()), self.qp.last_ddq.copy()

    def late_tick(self, before: tuple[np.ndarray | None, np.ndarray], out: TickOutput) -> TickOutput:
        """The command ``out`` of this tick was ready after its deadline (real time): it never reached the robot,
        which re-applies the last torque it received (``before``, from :meth:`command_state` at the start of the
        tick). The QP is put back to that torque and acceleration, so the next command's rate and jerk are measured
        against what the robot really applied. The planning the tick did (smoother, MPC, filter) stands."""
        tau, ddq = before
        if tau is None:  # no command yet: the robot holds its gravity compensation (h)
            tau = np.array(self.terms.h) if self.terms is not None else out.tau_nm
        self.qp.tau_last = np.array(tau, dtype=np.float64)
        self.qp.last_ddq = np.array(ddq, dtype=np.float64)
        return TickOutput(tau_nm=self.qp.tau_last, gripper_m=out.gripper_m, ref_pos_m=out.ref_pos_m,
                          ee_pos_m=out.ee_pos_m, ddq_cmd_rad_s2=self.qp.last_ddq, tcp_vel_m_s=out.tcp_vel_m_s)

    def missed_tick(self, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> TickOutput:
        """A control tick whose command never reached the robot: the robot re-applies the last torque it received.
        Nothing is planned; the QP records the held torque (the next command's rate is measured against it); the
        last commanded acceleration stands (no new command was sent)."""
        terms = self.terms = self.model.terms(q_rad, dq_rad_s)
        tau = self.qp.tau_last if self.qp.tau_last is not None else np.array(terms.h)
        ddq = self.qp.hold(tau)
        return TickOutput(tau_nm=self.qp.tau_last, gripper_m=self._gripper_m, ref_pos_m=np.full(3, np.nan),
                          ee_pos_m=terms.pos_m, ddq_cmd_rad_s2=ddq, tcp_vel_m_s=terms.vel[:3])
