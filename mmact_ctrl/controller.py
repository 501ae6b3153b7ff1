"""The 1 kHz control layer under the chunk source: executor reference (+ its correction: retargeting, a learned
residual) -> (Ruckig) -> (MPC) -> QP -> torques."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields, replace

import numpy as np

from controllers.mpc import MPCPlan, TaskSpaceMPC
from controllers.qp_id import TaskReference, TaskSpaceQP, commanded_accel
from controllers.robot_model import PandaModel, RobotTerms
from controllers.rotations import orientation_error, rot_from_rotvec, rotvec_from_rot
from controllers.smoother import TaskSpaceSmoother
from controllers.stop import StopTrajectory
from controllers.target_estimator import TargetEstimator
from controllers.tick_kernels import sample_plan_task
from mmact_ctrl.chunk import ActionChunk
from mmact_ctrl.config import StackConfig
from mmact_ctrl.executors import ChunkExecutor, make_executor
from mmact_ctrl.mpc_worker import InlineMPC
from mmact_ctrl.reference import ChunkReference

GRIPPER_OPEN_M = 0.08


@dataclass
class TickOutput:
    """What one control tick produced: the command, and what the safety monitor and the log need.

    Attributes:
        tau_nm (7,): the torque command, N*m.
        gripper_m: gripper opening command, m.
        ref_pos_m (3,): the task-space reference the tick tracked (before the MPC), m.
        ee_pos_m (3,): the TCP position (controller's model), m.
        ddq_cmd_rad_s2 (7,): the joint acceleration the command asks for in this state (``M^-1 (tau - h)``).
        tcp_vel_m_s (3,): the TCP linear velocity (controller's model), m/s.
    """

    tau_nm: np.ndarray
    gripper_m: float
    ref_pos_m: np.ndarray
    ee_pos_m: np.ndarray
    ddq_cmd_rad_s2: np.ndarray
    tcp_vel_m_s: np.ndarray


class HybridController:
    """Executes chunks at the control rate: the episode's chunk executor (``mmact_ctrl.executors``, one per
    ``StackConfig.mode``) gives the reference and says which layers run under it; the ``StackConfig`` switches
    each layer off. This class knows no mode names."""

    def __init__(self, config: StackConfig, model: PandaModel | None = None,
                 executor: ChunkExecutor | None = None) -> None:
        """Args:
            config: the stack's configuration.
            model: the robot model (None: the Panda's).
            executor: how chunks are executed (None: the built-in executor named ``config.mode``); any object that
                satisfies ``mmact_ctrl.executors.ChunkExecutor``.
        """
        self.config = config
        self.model = model if model is not None else PandaModel()
        self.qp = TaskSpaceQP(replace(config.qp, dt_s=config.dt_s))
        self.executor = executor if executor is not None else make_executor(config.mode)
        layers = self.executor.layers
        self.reads_target = layers.reads_target
        self.smoothing = layers.smooth and config.use_ruckig
        self.use_mpc = layers.preview and config.use_mpc
        # With MPC, Ruckig steps once per MPC period (its output is only read there); else every control tick.
        smoother_dt_s = 1.0 / config.mpc.rate_hz if self.use_mpc else config.dt_s
        self.smoother = TaskSpaceSmoother(replace(config.smoother, dt_s=smoother_dt_s))
        self.filter = TargetEstimator(replace(config.filter, dt_s=1.0 / config.perception_hz))
        # the MPC object never discards a slow solve itself: lateness is the worker's to judge (in real time, a plan
        # that arrives later than config.mpc.max_solve_ms; in simulated time none: results must not depend on load)
        self.mpc = (TaskSpaceMPC(replace(config.mpc, max_solve_ms=math.inf), q_nominal_rad=self.model.home_q_rad)
                    if self.use_mpc else None)
        self.mpc_worker = InlineMPC(self.mpc) if self.mpc is not None else None
        self.offpath_us = 0.0  # this tick's time on work real time does beside the command path (MPC update + solve), us
        self.after_us = 0.0  # the part of it real time does on the loop's thread after the command (the update), us
        self.recorded_plans: list | None = None  # a recording's list of (asked s, t0 s, dt s, TCP preview (N, 3))
        # real time: the MPC update asked for at a tick, done after the commands in two stages (:meth:`end_tick`)
        self._deferred_mpc: list | None = None
        self._mpc_period_s = 1.0 / config.mpc.rate_hz
        self._mpc_taus = config.mpc.dt_s * np.arange(1, config.mpc.horizon_steps + 1)
        self._plan: MPCPlan | None = None
        self._prev_plan: MPCPlan | None = None
        self._next_mpc_s = 0.0
        self.q_post = self.model.home_q_rad
        _, self.rot_nominal = self.model.fk(self.q_post)
        self.active: ChunkReference | None = None
        self._hold_pos = np.zeros(3)
        self._hold_rotvec = np.zeros(3)
        self._gripper_m = GRIPPER_OPEN_M
        self._smoothed_pos: np.ndarray | None = None
        self.terms: RobotTerms | None = None
        self.stop: StopTrajectory | None = None  # the watchdog's braking reference while no valid chunk covers now
        self.watchdog_stops = 0
        self.floor_clamps = 0  # reference samples raised to config.tcp_floor_m
        self.plan_resyncs = 0  # MPC plans started from the measured state because the robot left the tracked one
        self.mpc_bypass_ticks = 0  # ticks tracking the smoothed reference directly: no good MPC plan covered them
        self._good_plan_end_s = 0.0
        self.executor.bind(self)
        # the QP's rare paths (DAQP's rescue, the fallback) run once now, not for the first time inside an episode
        zeros7 = np.zeros(7)
        home = self.model.terms(self.q_post, zeros7)
        self.qp.warm_up(home, self.q_post, zeros7, TaskReference(np.array(home.pos_m), np.zeros(3), np.zeros(3),
                                                                 np.array(home.rot), np.zeros(3), np.zeros(3), self.q_post))

    @property
    def mode(self) -> str:
        """The executor's name (``StackConfig.mode`` unless an executor was given)."""
        return self.executor.name

    # ---- episode -----------------------------------------------------------
    def reset(self, q_rad: np.ndarray, dq_rad_s: np.ndarray | None = None) -> np.ndarray:
        """New episode: hold the current pose until the first chunk is active. Returns the torque the robot is
        taken to apply before the first command, ``h(q, dq)`` (gravity, Coriolis, damping: what a Panda's own
        gravity compensation does with a zero user torque); the first command's rate is measured against it."""
        q = np.asarray(q_rad, dtype=float)
        dq = np.zeros(7) if dq_rad_s is None else np.asarray(dq_rad_s, dtype=float)
        pos, rot = self.model.fk(q)
        self._hold_pos = pos
        self._hold_rotvec = rotvec_from_rot(rot, self.rot_nominal)
        self._gripper_m = GRIPPER_OPEN_M
        self._smoothed_pos = None
        self.smoother.reset(pos, self._hold_rotvec)
        self.filter = TargetEstimator(self.filter.config)
        tau_start = np.array(self.model.terms(q, dq).h)
        self.qp.reset(tau_start)
        self.stop = None
        self.watchdog_stops = 0
        self.floor_clamps = 0
        self.plan_resyncs = 0
        self.mpc_bypass_ticks = 0
        self._good_plan_end_s = 0.0
        self._plan = None
        self._prev_plan = None
        self._deferred_mpc = None
        self._next_mpc_s = self.config.mpc_phase_s
        # before the first MPC tick (a phase > 0) the QP holds the start pose, as it does without a plan
        self._slow_ref = (0.0, pos, np.zeros(3), np.zeros(3), rot, np.zeros(3), np.zeros(3), GRIPPER_OPEN_M)
        if self.mpc_worker is not None:  # keep the built problem (0.3 s to build), forget the episode
            self.mpc_worker.reset()
        self.active = None
        self.terms = None
        self.executor.reset()
        return tau_start

    def ee_pose(self, q_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """TCP position (m) and rotation vector relative to the nominal grasp (rad) at ``q``."""
        pos, rot = self.model.fk(q_rad)
        return pos, rotvec_from_rot(rot, self.rot_nominal)

    # ---- inputs at their own rates -------------------------------------------
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
        self.stop = None
        target_at_obs_m = self._target_at_observation(chunk.t0_s, target_at_obs_m)
        self.active = ChunkReference(chunk=chunk, t_active_s=t_s, target_at_obs_m=target_at_obs_m)
        self.executor.activate(self.active, t_s)

    def splice_distance_m(self, chunk: ActionChunk, t_s: float, target_at_obs_m: np.ndarray | None,
                          ee_at_obs_m: np.ndarray | None = None) -> float:
        """How far the reference would jump at ``t_s`` if ``chunk`` became active now, m: the distance from where it
        would start (the executor's correction included, :meth:`start_position`) to the nearest of what the robot is
        following or doing now: the raw reference, the Ruckig-smoothed one (with smoothing: any jump of the raw reference is absorbed
        and smoothed away, so a start near either is no jump) and the TCP itself (a chunk that starts where the arm
        is, as a source planning from the observed state does while a fast arm lags its reference, asks for no jump
        of the arm); or, given ``ee_at_obs_m``, the distance from the chunk's first waypoint to the TCP it was
        planned from, whichever is smallest."""
        start = self.start_position(chunk, t_s, target_at_obs_m)
        gap = float(np.linalg.norm(start - self.reference(t_s)[0]))
        if self.smoothing and self._smoothed_pos is not None:
            gap = min(gap, float(np.linalg.norm(start - self._smoothed_pos)))
        if self.terms is not None:
            gap = min(gap, float(np.linalg.norm(start - self.terms.pos_m)))
        if ee_at_obs_m is not None:
            # a chunk whose path begins where the TCP was when it was observed is a plan of the robot's own motion,
            # however late it arrives: a long inference delay puts its activation far along its path (the executor
            # then catches up within the QP's speed bounds); a corrupted chunk begins elsewhere
            gap = min(gap, float(np.linalg.norm(chunk.waypoints[0, :3] - np.asarray(ee_at_obs_m, dtype=float))))
        return gap

    def _target_at_observation(self, t0_s: float, recorded_m: np.ndarray | None) -> np.ndarray | None:
        """Where the target was at the chunk's observation time, as best known now: the filter's estimate from the
        measurements captured up to ``t0_s`` (``filtered_at``: with a sensor latency the estimate recorded at
        ``t0_s`` had to extrapolate over the latency, this one did not; with no latency they are the same), else the
        one recorded then, else the current estimate extrapolated back; then corrected for a jump the observation
        already saw (``estimate_at_observation``)."""
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

    # ---- the stale-chunk watchdog ----------------------------------------------------
    def covered(self, t_s: float) -> bool:
        """Whether a chunk (or, before the first one, the initial hold) covers ``t_s``."""
        return self.active is None or t_s <= self.active.t_last_s  # the newest chunk ends last

    def watchdog(self, t_s: float) -> bool:
        """No valid chunk covers ``t_s``: brake the reference to rest from where it is now, within the smoother's
        acceleration and jerk limits, and hold there until a new chunk is activated. Returns whether a stop
        started now (counted in ``watchdog_stops``); a stop already under way goes on."""
        if self.stop is not None:
            return False
        pos, vel, rotvec, rotvec_rate, gripper = self.reference(t_s)
        sc = self.config.smoother
        self.stop = StopTrajectory(t_s, np.concatenate([pos, rotvec, [gripper]]),
                                   np.concatenate([vel, rotvec_rate, [0.0]]), sc.a_max_m_s2, sc.j_max_m_s3,
                                   sc.dw_max_rad_s2, sc.ddw_max_rad_s3)
        self.watchdog_stops += 1
        return True

    # ---- the 1 kHz tick ------------------------------------------------------------
    def reference(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """(pos m, vel m/s, rotvec rad, rotvec rate rad/s, gripper m) before smoothing: the watchdog's stop, the hold
        before the first chunk, or the executor's sample of the executed chunk(s) plus its correction; never below
        ``config.tcp_floor_m`` (a raised sample has no downward velocity and counts in ``floor_clamps``)."""
        pos, vel, rotvec, rate, gripper = self._raw_reference(t_s)
        if pos[2] < self.config.tcp_floor_m:
            pos, (vel,) = self._raise_to_floor(pos, vel)
        return pos, vel, rotvec, rate, gripper

    def _raise_to_floor(self, pos: np.ndarray, *rates: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
        """``pos`` raised to ``config.tcp_floor_m`` (counted in ``floor_clamps``), its rates (velocity,
        acceleration) with no downward component left."""
        self.floor_clamps += 1
        up = tuple(np.array([r[0], r[1], max(r[2], 0.0)]) for r in rates)
        return np.array([pos[0], pos[1], self.config.tcp_floor_m]), up

    def _raw_reference(self, t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        if self.stop is not None:
            action, rate = self.stop.sample(t_s)
            return action[:3], rate[:3], action[3:6], rate[3:6], float(action[6])
        if self.active is None:
            return self._hold_pos, np.zeros(3), self._hold_rotvec, np.zeros(3), GRIPPER_OPEN_M
        action, rate = self.executor.sample(t_s, self.active)
        offset, offset_vel = self.executor.offset(t_s, self.active)
        return action[:3] + offset, rate[:3] + offset_vel, action[3:6], rate[3:6], float(action[6])

    def reference_positions(self, times_s: np.ndarray) -> np.ndarray:
        """Positions (N, 3) of :meth:`reference` at many times at once (the MPC's preview), vectorized."""
        times_s = np.asarray(times_s, dtype=float)
        if self.stop is not None:
            return self.stop.sample_positions(times_s)
        if self.active is None:
            return np.tile(self._hold_pos, (len(times_s), 1))
        pos = self.executor.sample_positions(times_s, self.active)
        offsets = self.executor.offsets_many(times_s, self.active)
        pos = pos if offsets is None else pos + offsets
        if np.any(pos[:, 2] < self.config.tcp_floor_m):  # a copy: the executor's array may be its own cache
            pos = pos.copy()
            pos[:, 2] = np.maximum(pos[:, 2], self.config.tcp_floor_m)
        return pos

    def _plan_start(self, t_s: float, q_rad, dq_rad_s, terms: RobotTerms):
        """Where a new MPC plan starts. ``config.mpc_plan_start == "measured"`` (default): the measured state (the
        MPC closes the loop on where the robot is; the hand-over step is spread by the plan blend). ``"tracked"``:
        the joint state of the current plan at ``t_s`` (the state the QP is tracking), so the TCP reference is
        continuous in position and velocity across the hand-over; the measured state when there is no plan yet,
        or when the TCP has left the tracked one by more than ``config.plan_resync_m`` / ``plan_resync_m_s``
        (counted in ``plan_resyncs``). Measured on a 0.3 m/s linear target (expert, 1-10 Hz): "tracked" lost the
        MPC's feedback where the rate-limited robot lagged its reference (tracking ratio 0.51 vs 0.65 on the
        hardest seeds), with no fewer ticks at the rate limit once plans are blended. The comparison is in task space: the QP tracks the TCP and only pulls the
        null space toward the plan's posture, so the joints may differ from the plan where the TCP does not.
        Returns (q, dq, TCP position, TCP rotation, Jacobian) at that state."""
        plan = self._plan
        if plan is not None and self.config.mpc_plan_start == "tracked":
            q_ref, dq_ref, _ = plan.sample(t_s)
            pos, rot, jac = self.model.kinematics(q_ref)
            if (np.linalg.norm(pos - terms.pos_m) <= self.config.plan_resync_m
                    and np.linalg.norm(jac[:3] @ dq_ref - terms.vel[:3]) <= self.config.plan_resync_m_s):
                return q_ref, dq_ref, pos, rot, jac
            self.plan_resyncs += 1
        return q_rad, dq_rad_s, terms.pos_m, terms.rot, terms.J

    def use_mpc_worker(self, worker) -> None:
        """Solve the MPC with ``worker`` (``mmact_ctrl.mpc_worker``: :class:`ProcessMPC` in real time) instead of
        inline; the previous worker is closed."""
        if self.mpc_worker is not None and self.mpc_worker is not worker:
            self.mpc_worker.close()
        self.mpc_worker = worker

    def _mpc_problem(self, t_s: float, q_rad, dq_rad_s, terms: RobotTerms, rot_des: np.ndarray) -> tuple:
        """The arguments of ``TaskSpaceMPC.solve`` after ``t_s``: preview the reference over the MPC horizon
        (retargeted chunk, predicted target, and the Ruckig offset still to be smoothed away), from
        :meth:`_plan_start` (copies: a worker thread may solve it while the loop goes on)."""
        taus = self._mpc_taus
        preview = self.reference_positions(t_s + taus)
        if self.smoothing and self.config.smoother.relative:
            preview = preview + self.smoother.preview_pos_offset(taus)
            preview[:, 2] = np.maximum(preview[:, 2], self.config.tcp_floor_m)
        q0, dq0, pos0, rot0, jac0 = self._plan_start(t_s, q_rad, dq_rad_s, terms)
        return (np.array(q0), np.array(dq0), np.array(pos0), np.array(jac0), preview, orientation_error(rot_des, rot0))

    def _smoothed_reference(self, t_s: float):
        """(pos, vel, acc, rot, ang_vel, ang_acc, gripper): the reference after retargeting and Ruckig."""
        pos, vel, rotvec, rotvec_rate, gripper = self.reference(t_s)
        if self.smoothing:
            pos, vel, acc, rotvec, ang_vel, ang_acc = self.smoother.step(pos, vel, rotvec, rotvec_rate)
            if pos[2] < self.config.tcp_floor_m:  # the smoother's decaying offset of a chunk switch may dip below it
                pos, (vel, acc) = self._raise_to_floor(pos, vel, acc)
            self._smoothed_pos = pos
        else:
            acc, ang_vel, ang_acc = np.zeros(3), rotvec_rate, np.zeros(3)
        return pos, vel, acc, rot_from_rotvec(rotvec, self.rot_nominal), ang_vel, ang_acc, gripper

    def tick(self, t_s: float, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> TickOutput:
        """One control period: torques for the measured joint state.

        Without MPC the reference is retargeted and Ruckig-smoothed every tick. With MPC the QP tracks
        the MPC plan, so retargeting and Ruckig run at the MPC's rate (their output is only read there;
        Ruckig then steps with the MPC period), and every tick only samples the plan. A failed or late MPC
        solve keeps the last plan (re-timed by the MPC's own fallback) for ``config.mpc_keep_plan_s`` after
        the last good solve; past that the QP tracks the smoothed reference directly (``mpc_bypass_ticks``):
        a stale plan's linearized TCP prediction drifts from the real TCP and is not followed for long.
        """
        terms = self.model.terms(q_rad, dq_rad_s)
        self.terms = terms
        self.offpath_us = 0.0
        self.after_us = 0.0
        if self.use_mpc:
            worker = self.mpc_worker
            if t_s >= self._next_mpc_s - 1e-9:
                if getattr(worker, "defer_submit", False):
                    # real time: the MPC's whole 50 Hz work (Ruckig at the MPC rate, the preview, the problem) is
                    # done once the tick's command is out (end_tick), not before it; this tick tracks the plan it has
                    self._deferred_mpc = [0, t_s, np.array(q_rad), np.array(dq_rad_s),
                                          RobotTerms(*(np.array(getattr(terms, f.name)) for f in fields(terms))), None]
                else:  # simulated time: at once, so the plan of this tick's state drives this tick (results kept)
                    a0, n_solved = time.perf_counter(), len(worker.solve_us)
                    self._mpc_update(t_s, q_rad, dq_rad_s, terms)
                    # what real time does after the command (the update) and in another process (the solve) is
                    # kept out of the command path's time (offpath_us); the update alone is after_us
                    self.offpath_us = (time.perf_counter() - a0) * 1e6
                    solve_us = worker.solve_us[-1] if len(worker.solve_us) > n_solved else 0.0
                    self.after_us = max(self.offpath_us - solve_us, 0.0)
                self._next_mpc_s = t_s + self._mpc_period_s
            done = worker.poll()
            if done is not None:  # the newest finished plan takes over
                t_asked, new_plan = done
                self._prev_plan = self._plan
                self._plan = new_plan
                if self.recorded_plans is not None:
                    self.recorded_plans.append((t_asked, new_plan.t0_s, new_plan.dt_s, np.array(new_plan.ee_pos_m)))
                if new_plan.ok:
                    self._good_plan_end_s = t_asked + self.config.mpc_keep_plan_s
            t_slow, ref_pos, ref_vel, ref_acc, rot, ang_vel, ang_acc, gripper = self._slow_ref
            plan = self._plan
            if plan is not None and (plan.ok or t_s < self._good_plan_end_s):
                q_post, task = np.empty(7), np.empty((3, 3))  # == plan.sample(t) and plan.sample_task(t), compiled
                sample_plan_task(t_s, plan.t0_s, plan.dt_s, plan.q_rad, plan.dq_rad_s, plan.ddq_rad_s2,
                                 plan.ee_pos_m[0], plan.ee_jacobian_lin, q_post, task)
                prev, blend_s = self._prev_plan, self.config.mpc_blend_s
                if prev is not None and t_s - plan.t0_s < blend_s:
                    # hand-over: the new plan's acceleration differs from the old one's; blend the two references
                    # with a smoothstep so the torque the QP needs ramps instead of stepping
                    q_old, task_old = np.empty(7), np.empty((3, 3))
                    sample_plan_task(t_s, prev.t0_s, prev.dt_s, prev.q_rad, prev.dq_rad_s, prev.ddq_rad_s2,
                                     prev.ee_pos_m[0], prev.ee_jacobian_lin, q_old, task_old)
                    x = (t_s - plan.t0_s) / blend_s
                    w = x * x * (3.0 - 2.0 * x)
                    task = task_old + w * (task - task_old)
                    q_post = q_old + w * (q_post - q_old)
                pos, vel, acc = task[0], task[1], task[2]
            else:  # the MPC has failed past the last good plan's horizon: the QP tracks the smoothed reference
                pos, vel, acc, q_post = ref_pos + ref_vel * (t_s - t_slow), ref_vel, ref_acc, self.q_post
                self.mpc_bypass_ticks += 1
        else:
            pos, vel, acc, rot, ang_vel, ang_acc, gripper = self._smoothed_reference(t_s)
            ref_pos, q_post = pos, self.q_post
        ref = TaskReference(
            pos_m=pos,
            vel_m_s=vel,
            acc_m_s2=acc,
            rot=rot,
            ang_vel_rad_s=ang_vel,
            ang_acc_rad_s2=ang_acc,
            q_post_rad=q_post,
        )
        tau = self.qp.solve(terms, q_rad, dq_rad_s, ref)
        self._gripper_m = gripper
        return TickOutput(tau_nm=tau, gripper_m=gripper, ref_pos_m=ref_pos, ee_pos_m=terms.pos_m,
                          ddq_cmd_rad_s2=self.qp.last_ddq, tcp_vel_m_s=terms.vel[:3])

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

    def _mpc_update(self, t_s: float, q_rad: np.ndarray, dq_rad_s: np.ndarray, terms: RobotTerms) -> None:
        """The MPC's work at its rate: the retargeted, Ruckig-smoothed reference at ``t_s`` (kept for the ticks
        until the next update), the problem previewed from the state of ``t_s``, handed to the worker."""
        rot = self._mpc_reference(t_s)
        self.mpc_worker.submit(t_s, self._mpc_problem(t_s, q_rad, dq_rad_s, terms, rot))

    def _mpc_reference(self, t_s: float) -> np.ndarray:
        """The first half of the MPC's update: the reference at ``t_s`` (kept in ``_slow_ref``); returns its
        rotation."""
        ref_pos, ref_vel, ref_acc, rot, ang_vel, ang_acc, gripper = self._smoothed_reference(t_s)
        self._slow_ref = (t_s, ref_pos, ref_vel, ref_acc, rot, ang_vel, ang_acc, gripper)
        return rot

    def end_tick(self, spare: bool = True) -> float:
        """After the tick's command is sent: a stage of the MPC update a deferring worker (real time) asked for.
        The update is done in two stages on two ticks, each after its command (the reference with Ruckig at the
        MPC's rate; then the preview and the problem, handed to the process, which solves while the loop waits for
        its next tick): at once it took about as long as a whole tick's budget on a slow machine, and the next tick
        then started late enough for its command to miss the deadline. ``spare=False`` (this tick's after-command
        work was long already, e.g. a chunk was admitted) waits a tick. Returns the time it took, us."""
        if self._deferred_mpc is None or not spare:
            return 0.0
        a0 = time.perf_counter()
        stage, t_s, q_rad, dq_rad_s, terms, rot = self._deferred_mpc
        if stage == 0:
            self._deferred_mpc[0], self._deferred_mpc[5] = 1, self._mpc_reference(t_s)
        else:
            self._deferred_mpc = None
            self.mpc_worker.submit(t_s, self._mpc_problem(t_s, q_rad, dq_rad_s, terms, rot))
        return (time.perf_counter() - a0) * 1e6

    def missed_tick(self, q_rad: np.ndarray, dq_rad_s: np.ndarray) -> TickOutput:
        """A control tick whose command never reached the robot: the robot re-applies the last torque it received.
        Nothing is planned; the QP records the held torque (the next command's rate is measured against it); the
        last commanded acceleration stands (no new command was sent)."""
        terms = self.model.terms(q_rad, dq_rad_s)
        self.terms = terms
        tau = self.qp.tau_last if self.qp.tau_last is not None else np.array(terms.h)
        ddq = self.qp.hold(tau)
        return TickOutput(tau_nm=self.qp.tau_last, gripper_m=self._gripper_m, ref_pos_m=np.full(3, np.nan),
                          ee_pos_m=terms.pos_m, ddq_cmd_rad_s2=ddq, tcp_vel_m_s=terms.vel[:3])
