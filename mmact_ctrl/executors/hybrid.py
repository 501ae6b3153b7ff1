"""``hybrid``: ours. The chunk is retargeted with the Kalman-filtered target (``controllers.retarget``: the
displacement of the target since the chunk's observation, gated by a trust radius), smoothed by Ruckig and
previewed by the MPC before the 1 kHz QP tracks it (each layer a ``StackConfig`` switch)."""

from __future__ import annotations

import numpy as np

from controllers.retarget import retarget_offset, retarget_offsets, trusted
from mmact_ctrl.executors.base import ClockedExecutor, Layers
from mmact_ctrl.reference import ChunkReference

_ZERO3 = np.zeros(3)


class HybridExecutor(ClockedExecutor):
    """Retargets the executed chunk with the target estimate; Ruckig and the MPC run under it."""

    name = "hybrid"
    layers = Layers(reads_target=True, smooth=True, preview=True)

    def __init__(self) -> None:
        super().__init__()
        self._trust: tuple[int, tuple] = (0, (False, None, None))  # (id of the chunk reference, _aim of it)

    def reset(self) -> None:
        self._trust = (0, (False, None, None))

    def _aim(self, ref: ChunkReference) -> tuple[bool, bool]:
        """(trusted, leading) of ``ref``, cached per reference. A chunk that comes to rest at its aim is trusted when
        the target estimate at its observation time is within the trust radius of the aim. A leading chunk (its
        tail runs at a constant velocity: :attr:`ChunkReference.aim_vel_m_s`) aims at a moving point: it is trusted
        when some waypoint of it comes within the trust radius of the target estimate predicted to that
        waypoint's time."""
        if self._trust[0] != id(ref):
            cfg = self.controller.config.retarget
            leading = bool(np.any(ref.aim_vel_m_s))
            ok = trusted(cfg, ref.aim_pos_m, ref.target_at_obs_m)
            if leading and ref.target_at_obs_m is not None and cfg.rule != "none" and self.controller.filter.initialized:
                pred = self.controller.filter.predict_pos_many(ref.chunk.times_s)
                ok = bool(np.min(np.linalg.norm(ref.chunk.waypoints[:, :3] - pred, axis=1)) <= cfg.trust_radius_m)
            self._trust = (id(ref), (ok, leading))
        return self._trust[1]

    def _alpha(self, times_s, ref: ChunkReference):
        """The pull's blend weight: 0 at activation, 1 at :meth:`_blend_end_s` (and its rate, 1/s)."""
        t0, t1 = ref.t_active_s, self._blend_end_s(ref)
        span = max(t1 - t0, 1e-6)
        alpha = np.clip((np.asarray(times_s, dtype=float) - t0) / span, 0.0, 1.0)
        return alpha, np.where((alpha > 0) & (alpha < 1), 1.0 / span, 0.0)

    def _blend_end_s(self, ref: ChunkReference) -> float:
        """The retargeting blend ends at the last waypoint of ``ref`` that will actually run: the next chunk is due
        one replan period after this one became active."""
        return min(ref.t_last_s, ref.t_active_s + 1.0 / self.controller.config.replan_hz)

    def offset(self, t_s: float, ref: ChunkReference) -> tuple[np.ndarray, np.ndarray]:
        """Resting chunk: ``controllers.retarget.retarget_offset``. Leading chunk: the chunk already follows the
        target's predicted course, so only the difference between where it is and where the estimate says the
        target is is pulled in, blended over the replan period: ``alpha(t) (p_hat(t) - w(t))`` (adding the target's
        displacement as for a resting chunk would count its motion twice)."""
        est = self.controller.filter
        ok, leading = self._aim(ref)
        if not (est.initialized and ok):
            return _ZERO3, _ZERO3
        cfg = self.controller.config.retarget
        if leading:
            (w, w_rate), (alpha, dalpha) = ref.sample(t_s), self._alpha(t_s, ref)
            gap = est.predict_pos(t_s) - w[:3]
            return float(alpha) * gap, float(alpha) * (est.predict_vel(t_s) - w_rate[:3]) + float(dalpha) * gap
        return retarget_offset(cfg, t_s, ref.aim_pos_m, ref.target_at_obs_m, est.predict_pos(t_s),
                               est.predict_vel(t_s), ref.t_active_s, self._blend_end_s(ref))

    def offsets_many(self, times_s: np.ndarray, ref: ChunkReference) -> np.ndarray | None:
        est = self.controller.filter
        ok, leading = self._aim(ref)
        if not (est.initialized and ok):
            return None
        pred = est.predict_pos_many(times_s)
        if leading:
            alpha, _ = self._alpha(times_s, ref)
            return alpha[:, None] * (pred - ref.sample_positions(times_s))
        return retarget_offsets(self.controller.config.retarget, times_s, ref.aim_pos_m, ref.target_at_obs_m, pred,
                                ref.t_active_s, self._blend_end_s(ref))
