"""``hybrid``: ours. The chunk is retargeted with the Kalman-filtered target (``controllers.retarget``: by default
``warp``, the chunk's path bent onto the estimate in proportion to its own progress; gated by a trust radius),
smoothed by Ruckig and previewed by the MPC before the 1 kHz QP tracks it (each layer a ``StackConfig`` switch)."""

from __future__ import annotations

import numpy as np

from controllers.retarget import progress, progresses, retarget_offset, retarget_offsets, trusted
from mmact_ctrl.executors.base import ZERO3, ClockedExecutor, Layers
from mmact_ctrl.reference import ChunkReference



_HORIZONTAL = np.array([1.0, 1.0, 0.0])


class HybridExecutor(ClockedExecutor):
    """Retargets the executed chunk with the target estimate; Ruckig and the MPC run under it."""

    name = "hybrid"
    layers = Layers(reads_target=True, smooth=True, preview=True)
    #: a leading chunk is pulled onto the estimate over this long after its activation (0: the replan period), s.
    #: Measured (expert with lead velocity, 0.3 m/s, 1 Hz, 200 ms, seeds 100-105, tracking ratio linear / reversal /
    #: swerve): the replan period 0.53 / 0.31 / 0.30, 0.5 s 0.61 / 0.45 / 0.46, 0.25 s 0.65 / 0.46 / 0.44, 0.1 s
    #: 0.66 / 0.50 / 0.50: the estimate (2 mm noise at 100 Hz) is better than any chunk's guess of the target.
    pull_s = 0.1

    def __init__(self) -> None:
        super().__init__()
        # caches keyed by the reference object itself (held, so it cannot be confused with a later one)
        self._trust: tuple[ChunkReference | None, tuple[bool, bool]] = (None, (False, False))  # (ref, _aim of it)
        self._last: ChunkReference | None = None  # the chunk executed before the active one
        self._carry: tuple[ChunkReference | None, np.ndarray] = (None, ZERO3)  # (leading ref, the step it carries)

    def reset(self) -> None:
        self._trust = (None, (False, False))
        self._last = None
        self._carry = (None, ZERO3)

    def activate(self, ref: ChunkReference, t_s: float) -> None:
        self._carry = (ref, self._carry_for(ref, t_s))
        self._last = ref

    def _carry_for(self, ref: ChunkReference, t_s: float) -> np.ndarray:
        """The step (3,) m from ``ref``'s raw position at ``t_s`` to the reference being executed then (the previous
        chunk with its correction): a leading chunk starts where that reference was and blends into its pull, so
        the hand-over does not jump (a resting chunk's rule is continuous by itself)."""
        if self._carry[0] is ref:
            return self._carry[1]
        prev = self._last
        ok, leading = self._aim(ref)
        if prev is None or prev is ref or not (ok and leading):
            return ZERO3
        return prev.sample(t_s)[0][:3] + self.offset(t_s, prev)[0] - ref.sample(t_s)[0][:3]

    def _aim(self, ref: ChunkReference) -> tuple[bool, bool]:
        """(trusted, leading) of ``ref``, cached per reference. A chunk that comes to rest at its aim is trusted when
        the target estimate at its observation time is within the trust radius of the aim. A chunk still moving at
        its end (:attr:`ChunkReference.at_rest` false: it leads a moving target, or its approach is not over) aims at
        a moving point: it is trusted when some waypoint of it comes within the trust radius of the target estimate
        predicted to that waypoint's time."""
        if self._trust[0] is not ref:
            cfg = self.view.config.retarget
            leading = not ref.at_rest
            ok = trusted(cfg, ref.aim_pos_m, ref.target_at_obs_m)
            if leading and ref.target_at_obs_m is not None and cfg.rule != "none" and self.view.estimate.initialized:
                pred = self.view.estimate.predict_pos_many(ref.chunk.times_s)
                ok = bool(np.min(np.linalg.norm(ref.chunk.waypoints[:, :3] - pred, axis=1)) <= cfg.trust_radius_m)
            self._trust = (ref, (ok, leading))
        return self._trust[1]

    @staticmethod
    def _pull_axes(cfg) -> np.ndarray | float:
        """The axes a chunk is retargeted on (``RetargetConfig.pull_axes``): all (1.0: reach's figures stay the same
        bit for bit), or x and y only."""
        return _HORIZONTAL if cfg.pull_axes == "xy" else 1.0

    def _pull_span_s(self, ref: ChunkReference) -> float:
        """How long the pull's blend weight takes from 0 (activation) to 1: ``pull_s``, or up to
        :meth:`_blend_end_s` if that is earlier, s."""
        t1 = self._blend_end_s(ref)
        if self.pull_s > 0:
            t1 = min(t1, ref.t_active_s + self.pull_s)
        return max(t1 - ref.t_active_s, 1e-6)

    def _blend_end_s(self, ref: ChunkReference) -> float:
        """The retargeting blend ends at the last waypoint of ``ref`` that will actually run: the next chunk is due
        one replan period after this one became active."""
        return min(ref.t_last_s, ref.t_active_s + 1.0 / self.view.config.replan_hz)

    def offset(self, t_s: float, ref: ChunkReference) -> tuple[np.ndarray, np.ndarray]:
        """A chunk at rest at its end: ``controllers.retarget.retarget_offset`` (the rule of ``config.retarget``;
        ``warp`` weighs the aim error by the chunk's progress along its path, ``controllers.retarget.progress``).
        A moving (leading) chunk already follows the target's predicted course (walls included, when its source
        knows them), so only the difference between where it is and where the estimate says the target is, is
        pulled in, blended over :meth:`_pull_span_s` from the step ``c`` it carries over from the previous reference
        (:meth:`_carry_for`): ``(1 - alpha(t)) c + alpha(t) (p_hat(t) - w(t))``, whatever the rule but ``none``
        (adding the target's displacement as for a resting chunk would count its motion twice)."""
        est = self.view.estimate
        ok, leading = self._aim(ref)
        if not (est.initialized and ok):
            return ZERO3, ZERO3
        cfg = self.view.config.retarget
        if leading:
            w, w_rate = ref.sample(t_s)
            span = self._pull_span_s(ref)
            alpha = min(max((t_s - ref.t_active_s) / span, 0.0), 1.0)
            dalpha = 1.0 / span if 0.0 < alpha < 1.0 else 0.0
            gap = (est.predict_pos(t_s) - w[:3]) * self._pull_axes(cfg)
            carry = self._carry_for(ref, ref.t_active_s)
            return ((1.0 - alpha) * carry + alpha * gap,
                    alpha * (est.predict_vel(t_s) - w_rate[:3]) * self._pull_axes(cfg) + dalpha * (gap - carry))
        weight = None
        if cfg.rule == "warp":
            w, w_rate = ref.sample(t_s)
            weight = progress(cfg, ref.aim_pos_m, ref.chunk.waypoints[0, :3], w[:3], w_rate[:3])
        offset, rate = retarget_offset(cfg, t_s, ref.aim_pos_m, ref.target_at_obs_m, est.predict_pos(t_s),
                                       est.predict_vel(t_s), ref.t_active_s, self._blend_end_s(ref), weight)
        return (offset * _HORIZONTAL, rate * _HORIZONTAL) if cfg.pull_axes == "xy" else (offset, rate)

    def offsets_many(self, times_s: np.ndarray, ref: ChunkReference) -> np.ndarray | None:
        est = self.view.estimate
        ok, leading = self._aim(ref)
        if not (est.initialized and ok):
            return None
        pred = est.predict_pos_many(times_s)
        if leading:
            alpha = np.clip((np.asarray(times_s, dtype=float) - ref.t_active_s) / self._pull_span_s(ref), 0.0, 1.0)
            carry = self._carry_for(ref, ref.t_active_s)
            gap = (pred - ref.sample_positions(times_s)) * self._pull_axes(self.view.config.retarget)
            return (1.0 - alpha)[:, None] * carry + alpha[:, None] * gap
        cfg = self.view.config.retarget
        weights = None
        if cfg.rule == "warp":
            weights = progresses(cfg, ref.aim_pos_m, ref.chunk.waypoints[0, :3], ref.sample_positions(times_s))
        offsets = retarget_offsets(cfg, times_s, ref.aim_pos_m, ref.target_at_obs_m, pred, ref.t_active_s,
                                   self._blend_end_s(ref), weights)
        return offsets * _HORIZONTAL if cfg.pull_axes == "xy" and offsets is not None else offsets
