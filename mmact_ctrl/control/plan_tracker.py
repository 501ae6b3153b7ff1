"""The MPC stage: at its rate (50 Hz) the smoothed reference is previewed over the MPC's horizon and a plan solved
(``controllers.mpc``, by a worker: inline, or a process in real time); at every tick the QP tracks the newest plan,
blended over the hand-over from the previous one, or the smoothed reference itself when no good plan covers the tick
(the bypass).

When the MPC's work is done is the tick order's (``mmact_ctrl.tick_order``): in simulated time at once, inside the
tick (the plan of this tick's state drives this tick); in the deadline order (real time) after the command, in two
stages on two ticks (:meth:`PlanTracker.after_command`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields
from typing import Callable

import numpy as np

from controllers.mpc import MPCPlan
from controllers.robot_model import PandaModel, RobotTerms
from controllers.rotations import orientation_error
from controllers.tick_kernels import sample_plan_blend, sample_plan_task
from mmact_ctrl.config import StackConfig
from mmact_ctrl.control.samples import SmoothedSample, TrackedReference

GRIPPER_OPEN_M = 0.08


@dataclass
class _Deferred:
    """An MPC update asked for at ``t_s`` and done after the commands (the deadline order): the state it was asked
    in, the stage it is at (0: the reference next; 1: the problem next) and the reference's rotation once known."""

    t_s: float
    q_rad: np.ndarray
    dq_rad_s: np.ndarray
    terms: RobotTerms
    stage: int = 0
    rot: np.ndarray | None = None


class PlanTracker:
    """Schedules the MPC, keeps its plans, and gives the QP what to track.

    Args:
        config: the stack's configuration (MPC rate and phase, blend, keep-plan time, plan start, floor).
        model: the robot model (the tracked state's kinematics).
        worker: solves the MPC (``mmact_ctrl.mpc_worker``).
        smoothed: the reference chain up to Ruckig, ``smoothed(t_s) -> SmoothedSample`` (advances the smoother).
        preview: the reference's positions (N, 3) at many times, floored (the MPC's preview).
        preview_offset: Ruckig's offset still to be smoothed away at many future delays (N, 3), or None.
        preview_low: the lowest heights the reference the QP tracks can reach at many future delays (N,), None when
            nothing bounds them yet (the descent governor's
            :meth:`~mmact_ctrl.control.descent.DescentGovernor.lowest_z_m`); the preview is held above them. None
            (reach, insert: no governor): the preview as it was.
    """

    def __init__(self, config: StackConfig, model: PandaModel, worker, smoothed: Callable[[float], SmoothedSample],
                 preview: Callable[[np.ndarray], np.ndarray], preview_offset: Callable[[np.ndarray], np.ndarray] | None,
                 preview_low: Callable[[np.ndarray], np.ndarray | None] | None = None):
        self.config, self.model, self.worker = config, model, worker
        self._smoothed, self._preview, self._preview_offset = smoothed, preview, preview_offset
        self._preview_low = preview_low
        self.q_post = model.home_q_rad
        self.period_s = 1.0 / config.mpc.rate_hz
        self._taus = config.mpc.dt_s * np.arange(1, config.mpc.horizon_steps + 1)
        self.defer_updates = False  # the deadline order: the MPC's work after the command (mmact_ctrl.tick_order)
        self.recorded_plans: list | None = None  # a recording's list of (asked s, t0 s, dt s, TCP preview (N, 3))
        self.offpath_us = 0.0  # this tick's time on work real time does beside the command path (update + solve), us
        self.after_us = 0.0  # the part of it real time does on the loop's thread after the command (the update), us
        self.reset(np.zeros(3), np.eye(3))

    def reset(self, pos_m: np.ndarray, rot: np.ndarray) -> None:
        """A new episode starting at the TCP pose ``pos_m`` / ``rot``: no plan; before the first MPC tick (a phase
        > 0) the QP holds that pose, as it does without a plan."""
        self.plan_resyncs = self.bypass_ticks = 0
        self._good_plan_end_s = 0.0
        self._plan: MPCPlan | None = None
        self._prev_plan: MPCPlan | None = None
        self._taken_s = 0.0  # when the plan's hand-over blend starts (see _take_newest)
        self._deferred: _Deferred | None = None
        self._next_s = self.config.mpc_phase_s
        z = np.zeros(3)
        self._slow_t_s = 0.0
        self._slow = SmoothedSample(pos_m, z, np.zeros(3), rot, np.zeros(3), np.zeros(3), GRIPPER_OPEN_M)
        if self.worker is not None:  # keep the built problem (0.3 s to build), forget the episode
            self.worker.reset()

    def use_worker(self, worker) -> None:
        """Solve with ``worker`` from now on (the previous one is closed)."""
        if self.worker is not None and self.worker is not worker:
            self.worker.close()
        self.worker = worker

    # ---- at every tick ---------------------------------------------------------------------------------------
    def track(self, t_s: float, q_rad: np.ndarray, dq_rad_s: np.ndarray, terms: RobotTerms) -> TrackedReference:
        """The MPC's update when due, the newest plan taken over, and what the QP tracks at ``t_s``."""
        self.offpath_us = self.after_us = 0.0
        if t_s >= self._next_s - 1e-9:
            self._update_due(t_s, q_rad, dq_rad_s, terms)
            self._next_s = t_s + self.period_s
        self._take_newest(t_s)
        plan = self._plan
        if plan is not None and (plan.ok or t_s < self._good_plan_end_s):
            q_post, task = self._sample(t_s, plan)
            return TrackedReference(task[0], task[1], task[2], q_post, self._slow)
        # the MPC has failed past the last good plan's horizon: the QP tracks the smoothed reference
        slow = self._slow
        self.bypass_ticks += 1
        return TrackedReference(slow.pos_m + slow.vel_m_s * (t_s - self._slow_t_s), slow.vel_m_s, slow.acc_m_s2,
                                self.q_post, slow)

    def _update_due(self, t_s: float, q_rad, dq_rad_s, terms: RobotTerms) -> None:
        if self.defer_updates:
            # real time: the MPC's whole 50 Hz work (Ruckig at the MPC rate, the preview, the problem) is done once
            # the tick's command is out (after_command), not before it; this tick tracks the plan it has
            self._deferred = _Deferred(t_s, np.array(q_rad), np.array(dq_rad_s),
                                       RobotTerms(*(np.array(getattr(terms, f.name)) for f in fields(terms))))
            return
        # simulated time: at once, so the plan of this tick's state drives this tick (results kept)
        a0, n_solved = time.perf_counter(), len(self.worker.solve_us)
        rot = self._reference(t_s)
        self.worker.submit(t_s, self._problem(t_s, q_rad, dq_rad_s, terms, rot))
        # what real time does after the command (the update) and in another process (the solve) is kept out of
        # the command path's time (offpath_us); the update alone is after_us
        self.offpath_us = (time.perf_counter() - a0) * 1e6
        solve_us = self.worker.solve_us[-1] if len(self.worker.solve_us) > n_solved else 0.0
        self.after_us = max(self.offpath_us - solve_us, 0.0)

    def _take_newest(self, t_s: float) -> None:
        done = self.worker.poll(t_s=t_s)
        if done is None:
            return
        t_asked, new_plan = done  # the newest finished plan takes over
        # blended in from the plan's start (inline: now; in real time a plan 2 ms late has 18 ms of blend left), or
        # from now, for a worker whose plans all come a fixed time late (a plan older than the blend would step in)
        self._taken_s = t_s if getattr(self.worker, "blends_from_take", False) else new_plan.t0_s
        self._prev_plan, self._plan = self._plan, new_plan
        if self.recorded_plans is not None:
            self.recorded_plans.append((t_asked, new_plan.t0_s, new_plan.dt_s, np.array(new_plan.ee_pos_m)))
        if new_plan.ok:
            self._good_plan_end_s = t_asked + self.config.mpc_keep_plan_s

    def _sample(self, t_s: float, plan: MPCPlan) -> tuple[np.ndarray, np.ndarray]:
        """(posture (7,), TCP (pos, vel, acc) rows (3, 3)) of ``plan`` at ``t_s``, blended with the previous plan's
        over the hand-over: the new plan's acceleration differs from the old one's, and a smoothstep between the two
        references ramps the torque the QP needs instead of stepping it."""
        q_post, task = np.empty(7), np.empty((3, 3))  # == plan.sample(t) and plan.sample_task(t), compiled
        prev = self._prev_plan
        if prev is not None and t_s - self._taken_s < self.config.mpc_blend_s:  # the smoothstep, compiled
            sample_plan_blend(t_s, plan.t0_s, plan.dt_s, plan.q_rad, plan.dq_rad_s, plan.ddq_rad_s2, plan.ee_pos_m[0],
                              plan.ee_jacobian_lin, prev.t0_s, prev.dt_s, prev.q_rad, prev.dq_rad_s, prev.ddq_rad_s2,
                              prev.ee_pos_m[0], prev.ee_jacobian_lin, self._taken_s, self.config.mpc_blend_s, q_post,
                              task)
        else:
            sample_plan_task(t_s, plan.t0_s, plan.dt_s, plan.q_rad, plan.dq_rad_s, plan.ddq_rad_s2, plan.ee_pos_m[0],
                             plan.ee_jacobian_lin, q_post, task)
        return q_post, task

    # ---- the update, at the MPC's rate ----------------------------------------------------------------------
    def _reference(self, t_s: float) -> np.ndarray:
        """The first half of the MPC's update: the smoothed reference at ``t_s`` (kept for the ticks until the next
        update); returns its rotation."""
        self._slow_t_s, self._slow = t_s, self._smoothed(t_s)
        return self._slow.rot

    def _problem(self, t_s: float, q_rad, dq_rad_s, terms: RobotTerms, rot_des: np.ndarray) -> tuple:
        """The arguments of ``TaskSpaceMPC.solve`` after ``t_s``: the reference previewed over the MPC horizon (the
        retargeted chunk, the predicted target, and Ruckig's offset still to be smoothed away), from
        :meth:`_plan_start` (copies: a worker may solve it while the loop goes on)."""
        taus = self._taus
        preview = self._preview(t_s + taus)
        if self._preview_offset is not None:
            preview = preview + self._preview_offset(taus)
            preview[:, 2] = np.maximum(preview[:, 2], self.config.tcp_floor_m)
        # not below what the descent governor will let the reference reach (a copy: the executor's array may be its
        # own cache)
        low = self._preview_low(taus) if self._preview_low is not None else None
        if low is not None:
            preview = np.array(preview)
            preview[:, 2] = np.maximum(preview[:, 2], low)
        q0, dq0, pos0, rot0, jac0 = self._plan_start(t_s, q_rad, dq_rad_s, terms)
        return (np.array(q0), np.array(dq0), np.array(pos0), np.array(jac0), preview, orientation_error(rot_des, rot0))

    def _plan_start(self, t_s: float, q_rad, dq_rad_s, terms: RobotTerms):
        """Where a new plan starts. ``config.mpc_plan_start == "measured"`` (default): the measured state (the MPC
        closes the loop on where the robot is; the hand-over step is spread by the plan blend). ``"tracked"``: the
        joint state of the current plan at ``t_s`` (the state the QP is tracking), so the TCP reference is continuous
        across the hand-over; the measured state when there is no plan yet, or when the TCP has left the tracked one
        by more than ``config.plan_resync_m`` / ``plan_resync_m_s`` (counted in ``plan_resyncs``). Measured on a 0.3
        m/s linear target (expert, 1-10 Hz): "tracked" lost the MPC's feedback where the rate-limited robot lagged its
        reference (tracking ratio 0.51 vs 0.65 on the hardest seeds). Returns (q, dq, TCP position, TCP rotation,
        Jacobian) at that state."""
        plan = self._plan
        if plan is not None and self.config.mpc_plan_start == "tracked":
            q_ref, dq_ref, _ = plan.sample(t_s)
            pos, rot, jac = self.model.kinematics(q_ref)
            if (np.linalg.norm(pos - terms.pos_m) <= self.config.plan_resync_m
                    and np.linalg.norm(jac[:3] @ dq_ref - terms.vel[:3]) <= self.config.plan_resync_m_s):
                return q_ref, dq_ref, pos, rot, jac
            self.plan_resyncs += 1
        return q_rad, dq_rad_s, terms.pos_m, terms.rot, terms.J

    def after_command(self, spare: bool = True) -> float:
        """The deadline order, after the tick's command is sent: a stage of a deferred update, in two stages on two
        ticks (the reference with Ruckig at the MPC's rate; then the preview and the problem, handed to the worker,
        which solves while the loop waits for its next tick): at once it took about a whole tick's budget on a slow
        machine, and the next command then missed its deadline. ``spare=False`` (this tick's after-command work was
        long already, e.g. a chunk was admitted) waits a tick. Returns the time it took, us."""
        d = self._deferred
        if d is None or not spare:
            return 0.0
        a0 = time.perf_counter()
        if d.stage == 0:
            d.stage, d.rot = 1, self._reference(d.t_s)
        else:
            self._deferred = None
            self.worker.submit(d.t_s, self._problem(d.t_s, d.q_rad, d.dq_rad_s, d.terms, d.rot))
        return (time.perf_counter() - a0) * 1e6
