""":class:`TargetEstimator`: the 3-D target tracker the stack runs, with latency-aware, out-of-order-safe fusion.

``fuse(t_capture_s, z)`` takes a measurement of the target *as it was* at its capture time, however late it arrives.
The state lives at the last fused capture time ``t_s``; it is propagated to each new capture time with the real time
difference (:mod:`~controllers.estimation.propagation`) and updated there, and :meth:`TargetEstimator.predict_pos`
extrapolates to *now* with the model (:mod:`~controllers.estimation.motion_models`). A measurement captured before
the newest one already processed (out of order) but within ``history_s`` of it rolls the estimator back to the state
stored just before it and re-fuses the later stored measurements in capture order
(:mod:`~controllers.estimation.history`), so the result does not depend on the arrival order; an older one is
dropped (``dropped_old``). Every measurement passes the gates first (:mod:`~controllers.estimation.gates`);
agreeing outliers are a jump (:mod:`~controllers.estimation.jumps`).
"""

from __future__ import annotations

import math

import numpy as np

from controllers.estimation import history as _history
from controllers.estimation import jumps as _jumps
from controllers.estimation.config import EstimatorConfig
from controllers.estimation.gates import innovation_d2, screen
from controllers.estimation.history import HistoryEntry
from controllers.estimation.jumps import NO_RUN, Jump, extend_run
from controllers.estimation.motion_models import make_motion_model
from controllers.estimation.propagation import propagation_steps


class TargetEstimator:
    """3-D target tracker with latency-aware, out-of-order-safe fusion. Positions in m, velocities in m/s, times s.

    ``fuse(t_capture_s, z)`` whenever a measurement arrives (stamped with its capture time); ``step(t_s, z)`` is the
    zero-latency fixed-step filter contract; ``predict_pos(t_s)`` any time."""

    def __init__(self, config: EstimatorConfig = EstimatorConfig()) -> None:
        self.config = config
        self._model = make_motion_model(config)
        self._state: tuple | None = None
        self._R = np.eye(3) * config.meas_noise_m**2
        self.initialized = False
        self.t_s = 0.0  # the last fused capture time: the time of the state
        self.resets = 0
        self.missed = 0
        self.fused = 0
        self.gated_nonfinite = 0
        self.gated_frozen = 0
        self.gated_outlier = 0
        self.coasts = 0
        self.dropped_old = 0  # out-of-order measurements older than history_s (or than the stored history)
        self.reordered = 0  # out-of-order measurements re-fused in capture order
        self._gated_run = NO_RUN  # the outliers in a row that agree: a jump in the making
        self._jump: Jump | None = None  # the last confirmed jump
        self._last_z: np.ndarray | None = None
        self._clock_s = -math.inf  # the newest time seen (fused, gated or missed): decides the coast
        self._coast_counted_for: float | None = None
        self._history: list[HistoryEntry] = []

    # ---- counters and estimates --------------------------------------------------------
    @property
    def gated(self) -> int:
        """Measurements rejected by the gate (non-finite, frozen, outlier)."""
        return self.gated_nonfinite + self.gated_frozen + self.gated_outlier

    @property
    def pos_m(self) -> np.ndarray:
        """Position estimate at the last fused capture time ``t_s``, m."""
        return self._model.mean(self._state)[:3].copy() if self._state is not None else np.zeros(3)

    @property
    def vel_m_s(self) -> np.ndarray:
        """Velocity estimate at ``t_s`` (zero while coasting), m/s."""
        if self._state is None or self._coasting():
            return np.zeros(3)
        return self._model.mean(self._state)[3:6].copy()

    @property
    def mode_probs(self) -> np.ndarray | None:
        """IMM mode probabilities at ``t_s``: (p_cv, p_ca) for imm, (p_cv, p_ca, p_ct) for imm-ct; None for the
        single models."""
        return None if self._state is None else self._model.mode_probs(self._state)

    @property
    def history_len(self) -> int:
        return len(self._history)

    @property
    def jump_started_s(self) -> float | None:
        """The last confirmed jump: capture time of its first measurement, s (None before any)."""
        return None if self._jump is None else self._jump.started_s

    @property
    def reset_at_s(self) -> float | None:
        """The last confirmed jump: capture time of the re-initialisation, s."""
        return None if self._jump is None else self._jump.reset_at_s

    @property
    def reset_pos_m(self) -> np.ndarray | None:
        """The last confirmed jump: where the estimator re-initialised, m."""
        return None if self._jump is None else self._jump.pos_m

    # ---- fusion ------------------------------------------------------------------------
    def step(self, t_s: float, z_m: np.ndarray | None) -> str:
        """The zero-latency fixed-step filter contract: ``fuse(t_s, z_m)``."""
        return self.fuse(t_s, z_m)

    def fuse(self, t_capture_s: float, z_m: np.ndarray | None) -> str:
        """Fuse a measurement of the target as it was at ``t_capture_s`` (it may arrive late).

        Returns what happened: ``"missed"`` (None), ``"nonfinite"``/``"frozen"``/``"outlier"`` (gated, counted),
        ``"dropped"`` (out of order and older than ``history_s``: counted in ``dropped_old``), ``"reset"`` (a
        confirmed jump: re-initialised), ``"init"`` or ``"fused"``. An out-of-order measurement within
        ``history_s`` returns its own outcome after the later ones were re-fused. Never raises on a bad value."""
        try:
            t = float(t_capture_s)
        except (TypeError, ValueError):
            t = math.nan
        if not math.isfinite(t):  # a bad time stamp: gated as non-finite
            self.gated_nonfinite += 1
            return "nonfinite"
        self._advance_clock(t)
        if z_m is None:
            if self.initialized:
                self.missed += 1
            return "missed"
        z, gated = screen(z_m, self._last_z, self.config.frozen_gate)
        if z is None:
            if gated == "nonfinite":
                self.gated_nonfinite += 1
            else:
                self.gated_frozen += 1
            return gated
        self._last_z = z
        hist = self._history
        if not hist or t >= hist[-1].t_s:
            return self._record_and_process(t, z)
        return self._fuse_out_of_order(t, z)

    def _fuse_out_of_order(self, t: float, z: np.ndarray) -> str:
        """Roll back to the state before the first later measurement and re-fuse in capture order (or drop)."""
        hist = self._history
        k = _history.rollback_index(hist, t, self.config.history_s)
        if k is None:
            self.dropped_old += 1
            return "dropped"
        self.reordered += 1
        later = hist[k:]
        del hist[k:]
        self._restore(later[0].before)
        status = self._record_and_process(t, z)
        for e in later:
            self._record_and_process(e.t_s, e.z_m)
        return status

    def _advance_clock(self, t: float) -> None:
        if t > self._clock_s:
            self._clock_s = t
        if self._coasting() and self._coast_counted_for != self.t_s:
            mean = self._model.mean(self._state)
            if np.any(mean[3:]):  # as the fixed-step filter: a coast of an estimate that has motion
                self.coasts += 1
            self._coast_counted_for = self.t_s

    def _coasting(self) -> bool:
        return self.initialized and self._clock_s - self.t_s > self.config.coast_s

    def _record_and_process(self, t: float, z: np.ndarray) -> str:
        hist = self._history
        hist.append(HistoryEntry(t, z, self._save(), hist[-1].t_s if hist else -math.inf))
        status = self._process(t, z)
        _history.trim(hist, t - self.config.history_s)
        return status

    def _save(self) -> tuple:
        """The snapshot a history entry keeps; its first three fields (state, initialized, t_s) are read by
        :meth:`filtered_at`."""
        return (self._state, self.initialized, self.t_s, self._gated_run, self.fused, self.gated_outlier,
                self.resets, self._jump)

    def _restore(self, snap: tuple) -> None:
        (self._state, self.initialized, self.t_s, self._gated_run, self.fused, self.gated_outlier, self.resets,
         self._jump) = snap

    def _init_on(self, t: float, z: np.ndarray) -> None:
        self._state = self._model.init_state(z)
        self.t_s = t
        self.initialized = True
        self._gated_run = NO_RUN

    def _process(self, t: float, z: np.ndarray) -> str:
        """The outlier gate and the update for a screened measurement, in capture order."""
        if not self.initialized:
            self._init_on(t, z)
            return "init"
        c = self.config
        pred = self._model.predict(self._state, propagation_steps(t - self.t_s, c.coast_s, c.dt_s))
        if innovation_d2(z, pred.x, pred.P, self._R) > c.reset_gate:
            return self._gated_outlier_or_jump(t, z)
        self._gated_run = NO_RUN
        self._state = self._model.update(pred, z)
        self.t_s = t
        self.fused += 1
        return "fused"

    def _gated_outlier_or_jump(self, t: float, z: np.ndarray) -> str:
        """An outlier: counted, or, the ``reset_after``-th agreeing one in a row, a confirmed jump (re-initialise)."""
        c = self.config
        run = self._gated_run = extend_run(self._gated_run, z, t, c.jump_agree_m)
        if run.count >= c.reset_after:
            self.resets += 1
            self._init_on(t, z)
            self._jump = Jump(run.since_s, t, z.copy())
            return "reset"
        self.gated_outlier += 1
        return "outlier"

    # ---- prediction --------------------------------------------------------------------
    def _taus(self, times_s) -> np.ndarray:
        taus = np.asarray(times_s, dtype=float) - self.t_s
        if self._coasting():  # the motion estimate was dropped at t_s + coast_s: the target stands there
            taus = np.minimum(taus, self.config.coast_s)
        return taus

    def predict_pos(self, t_s: float) -> np.ndarray:
        """Predicted position at ``t_s`` (normally >= ``t_s`` of the state: now, or later), with the model (imm: the
        mode-probability-weighted extrapolation), m."""
        if self._state is None:
            return np.zeros(3)
        return self._model.extrapolate(self._state, self._taus(np.array([t_s])))[0]

    def predict_pos_many(self, times_s: np.ndarray) -> np.ndarray:
        """Predicted positions (N, 3) at ``times_s`` (N,): :meth:`predict_pos`, vectorized."""
        times = np.asarray(times_s, dtype=float).reshape(-1)
        if self._state is None:
            return np.zeros((times.size, 3))
        return self._model.extrapolate(self._state, self._taus(times))

    def predict_vel(self, t_s: float) -> np.ndarray:
        """Predicted velocity at ``t_s`` (ca/imm: with the acceleration; zero while coasting), m/s."""
        if self._state is None or self._coasting():
            return np.zeros(3)
        return self._model.extrapolate_vel(self._state, np.array([float(t_s) - self.t_s]))[0]

    def filtered_at(self, t_s: float) -> np.ndarray | None:
        """The estimate of the position at ``t_s`` from the measurements *captured* up to ``t_s`` only, as known now:
        with a sensor latency, the estimate taken at ``t_s`` itself had to extrapolate over the latency, this one
        (from the history) did not. None when the history does not reach back to ``t_s`` or no estimate existed then;
        the current estimate extrapolated when every stored capture is at or before ``t_s``."""
        entry = _history.first_after(self._history, t_s)
        if entry is None:
            return self.predict_pos(t_s) if self.initialized else None
        state, initialized, t_state = entry.before[0], entry.before[1], entry.before[2]
        if not initialized or state is None or t_state > t_s:
            return None
        return self._model.extrapolate(state, np.array([t_s - t_state]))[0]

    def estimate_at_observation(self, t0_s: float, recorded_m: np.ndarray | None) -> np.ndarray | None:
        """The best estimate of where the target was at an observation time ``t0_s``, given what is known now, on
        capture times: ``recorded_m`` (the estimate taken at ``t0_s``), or the post-jump position if a jump confirmed
        since then had already begun at ``t0_s`` (:func:`controllers.estimation.jumps.estimate_at_observation`)."""
        return _jumps.estimate_at_observation(self._jump, t0_s, recorded_m, self.config.dt_s)
