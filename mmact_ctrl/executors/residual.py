"""``residual``: an A2C2-style learned residual (arXiv 2509.23224). At the perception rate a small network
(``policy.residual.ResidualPolicy``, trained by ``python -m scenarios.train_residual``) takes the base waypoint being
executed, the time since the chunk's observation, the latest target measurements of the 100 Hz channel (the one
hybrid reads: the latest and the one ``history_s`` before it, nothing more) and the TCP state, and outputs a bounded
task-space correction; the 1 kHz QP tracks base waypoint + correction (held between updates). No retargeting, no
Ruckig, no MPC: the correction is the only layer.
"""

from __future__ import annotations

import numpy as np

from mmact_ctrl.executors.base import ClockedExecutor, Layers
from mmact_ctrl.reference import ChunkReference

_ZERO3 = np.zeros(3)


class ResidualExecutor(ClockedExecutor):
    """Executes the newest chunk plus the learned correction, updated at ``StackConfig.perception_hz``."""

    name = "residual"
    layers = Layers(reads_target=True)

    def __init__(self, policy=None) -> None:
        """Args:
            policy: a ``policy.residual.ResidualPolicy`` (None: the checkpoint ``StackConfig.residual_checkpoint``,
                or the shipped one, loaded when the executor is bound)."""
        super().__init__()
        self.policy = policy
        self._meas: list[tuple[float, np.ndarray]] = []  # (t_capture_s, pos_m) of the measurements seen, oldest first
        self._corr = _ZERO3
        self._next_update_s = 0.0
        self._period_s = 0.01
        self.updates = 0

    def bind(self, controller) -> None:
        super().bind(controller)
        if self.policy is None:
            from policy.residual import DEFAULT_RESIDUAL_CHECKPOINT, ResidualPolicy

            path = controller.config.residual_checkpoint or DEFAULT_RESIDUAL_CHECKPOINT
            self.policy = ResidualPolicy.load(path)
        self._period_s = 1.0 / controller.config.perception_hz

    def reset(self) -> None:
        self._meas = []
        self._corr = _ZERO3
        self._next_update_s = 0.0
        self.updates = 0

    def perceive(self, t_capture_s: float, z_m: np.ndarray | None) -> None:
        if z_m is None or not np.all(np.isfinite(z_m)):
            return
        self._meas.append((float(t_capture_s), np.asarray(z_m, dtype=float).copy()))
        keep_s = 2.0 * self.policy.config.history_s + 0.1
        while len(self._meas) > 2 and self._meas[0][0] < t_capture_s - keep_s:
            self._meas.pop(0)

    def _measurements(self) -> tuple[np.ndarray, np.ndarray, float] | None:
        """(latest, the one ``history_s`` before it, their time gap s), or None before the first measurement."""
        if not self._meas:
            return None
        t_last, z_last = self._meas[-1]
        want = t_last - self.policy.config.history_s
        t_prev, z_prev = self._meas[0]
        for t, z in self._meas:  # the newest measurement at least history_s older than the latest
            if t <= want + 1e-9:
                t_prev, z_prev = t, z
        return z_last, z_prev, max(t_last - t_prev, 0.0)

    def _correction(self, t_s: float, ref: ChunkReference) -> np.ndarray:
        from policy.residual import residual_features

        meas = self._measurements()
        terms = self.controller.terms
        if meas is None or terms is None:
            return _ZERO3
        z, z_prev, gap_s = meas
        base = ref.sample(t_s)[0][:3]
        chunk = ref.chunk
        feats = residual_features(base, t_s - chunk.t0_s, chunk.horizon * chunk.dt_s, z, z_prev, gap_s,
                                  terms.pos_m, terms.vel[:3])
        corr = np.asarray(self.policy.correction_m(feats), dtype=float).reshape(3)
        return corr if np.all(np.isfinite(corr)) else _ZERO3

    def offset(self, t_s: float, ref: ChunkReference) -> tuple[np.ndarray, np.ndarray]:
        active = self.controller.active
        if ref is not active:  # a candidate chunk (the splice check): its correction now
            return self._correction(t_s, ref), _ZERO3
        if t_s >= self._next_update_s - 1e-9:
            self._corr = self._correction(t_s, ref)
            self._next_update_s = t_s + self._period_s
            self.updates += 1
        return self._corr, _ZERO3
