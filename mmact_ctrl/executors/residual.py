"""``residual``: an A2C2-style learned residual (arXiv 2509.23224). At the perception rate a small network
(``policy.residual.ResidualPolicy``, trained by ``python -m scenarios.train_residual``) takes the base waypoint being
executed, the time since the chunk's observation, the latest target measurements of the 100 Hz channel (the one
hybrid reads: the latest and the one ``history_s`` before it, nothing more) and the TCP state, and outputs a bounded
task-space correction; the 1 kHz QP tracks base waypoint + correction. No retargeting, no Ruckig, no MPC: the
correction is the only layer.

The correction applied moves toward each new network output at most ``max_rate_m_s`` and is interpolated between
updates (a first-order hold: continuous, one update late). When a new chunk becomes active, the correction is
re-expressed against the new base chunk so that the reference does not jump (``c = previous reference - new
base``) and then moves toward the network's output for the new base: a source that plans from the measured TCP
(which the correction has already moved) is not corrected twice.
"""

from __future__ import annotations

import numpy as np

from mmact_ctrl.executors.base import ZERO3, ClockedExecutor, Layers
from mmact_ctrl.reference import ChunkReference



class ResidualExecutor(ClockedExecutor):
    """Executes the newest chunk plus the learned correction, updated at ``StackConfig.perception_hz``."""

    name = "residual"
    layers = Layers(reads_target=True)
    #: the applied correction moves at most this fast toward the network's output, m/s
    max_rate_m_s = 1.0

    def __init__(self, policy=None) -> None:
        """Args:
            policy: a ``policy.residual.ResidualPolicy`` (None: the checkpoint ``StackConfig.residual_checkpoint``,
                or the shipped one, loaded when the executor is bound)."""
        super().__init__()
        self.policy = policy
        self._meas: list[tuple[float, np.ndarray]] = []  # (t_capture_s, pos_m) of the measurements seen, oldest first
        self._base: ChunkReference | None = None  # the chunk the applied correction is relative to
        self._from = ZERO3  # the applied correction at the last update
        self._to = ZERO3  # ... and one update period later
        self._t_update_s = -1.0
        self._next_update_s = 0.0
        self._period_s = 0.01
        self.updates = 0

    def bind(self, view) -> None:
        super().bind(view)
        if self.policy is None:
            from policy.residual import DEFAULT_RESIDUAL_CHECKPOINT, ResidualPolicy

            path = view.config.residual_checkpoint or DEFAULT_RESIDUAL_CHECKPOINT
            self.policy = ResidualPolicy.load(path)
        self._period_s = 1.0 / view.config.perception_hz

    def reset(self) -> None:
        self._meas = []
        self._base = None
        self._from = ZERO3
        self._to = ZERO3
        self._t_update_s = -1.0
        self._next_update_s = 0.0
        self.updates = 0

    def activate(self, ref: ChunkReference, t_s: float) -> None:
        carry = self._carry(t_s, ref)
        self._base = ref
        self._from = self._to = carry
        self._t_update_s = t_s
        self._next_update_s = t_s  # the network's correction for the new base from this tick on

    def _carry(self, t_s: float, ref: ChunkReference) -> np.ndarray:
        """The correction that keeps the reference where it is when ``ref`` replaces the current base chunk."""
        if self._base is None:
            return ZERO3
        return self._base.sample(t_s)[0][:3] + self._hold(t_s)[0] - ref.sample(t_s)[0][:3]

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
        tcp_pos, tcp_vel = self.view.tcp_pos_m, self.view.tcp_vel_m_s
        if meas is None or tcp_pos is None:
            return ZERO3
        z, z_prev, gap_s = meas
        base = ref.sample(t_s)[0][:3]
        chunk = ref.chunk
        feats = residual_features(base, t_s - chunk.t0_s, chunk.horizon * chunk.dt_s, z, z_prev, gap_s,
                                  tcp_pos, tcp_vel)
        corr = np.asarray(self.policy.correction_m(feats), dtype=float).reshape(3)
        return corr if np.all(np.isfinite(corr)) else ZERO3

    def offset(self, t_s: float, ref: ChunkReference) -> tuple[np.ndarray, np.ndarray]:
        """The applied correction at ``t_s`` for the active chunk; for a candidate (the splice check), the correction
        it would start with (:meth:`_carry`)."""
        if ref is not self._base:
            return self._carry(t_s, ref), ZERO3
        if t_s >= self._next_update_s - 1e-9:
            now = self._hold(t_s)[0]
            step = self._correction(t_s, ref) - now
            limit = self.max_rate_m_s * self._period_s
            norm = float(np.linalg.norm(step))
            if norm > limit:
                step = step * (limit / norm)
            self._from, self._to, self._t_update_s = now, now + step, t_s
            self._next_update_s = t_s + self._period_s
            self.updates += 1
        return self._hold(t_s)

    def _hold(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The first-order hold between the last update and the next: (correction m, its rate m/s)."""
        if self._t_update_s < 0:
            return ZERO3, ZERO3
        x = min(max((t_s - self._t_update_s) / self._period_s, 0.0), 1.0)
        rate = (self._to - self._from) / self._period_s if x < 1.0 else ZERO3
        return self._from + x * (self._to - self._from), rate
