"""Where target measurements come from: a sensor with its own rate and latency, behind one small protocol.

The loop polls the sensor every control tick; a sensor returns the measurements that have *arrived* by then,
each stamped with the time its scene was captured, and the filter fuses each at its capture time
(``controllers.target_estimator``). Two sensors implement it:

- :class:`OracleSensor` (here): the world's ``measure_target()`` (truth + Gaussian noise, random dropout) at
  ``rate_hz``, delivered ``latency_ms`` after capture. With zero latency it is exactly the channel the stack
  always had.
- ``scenarios.world.camera_sensor.CameraSensor``: the instructed ball measured from rendered depth and segmentation
  images of a scene camera (pixel-quantized, depth noise growing with distance, real occlusion by the arm).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from mmact_ctrl.world import World


@dataclass(frozen=True)
class Measurement:
    """One target measurement: the scene at ``t_capture_s``, available from ``t_arrival_s`` on; ``pos_m`` (3,)
    world frame, or None when the sensor saw nothing (dropout, occlusion)."""

    t_capture_s: float
    t_arrival_s: float
    pos_m: np.ndarray | None


class TargetSensor(Protocol):
    """A target sensor: ``reset`` at the start of an episode, ``poll`` every control tick."""

    def reset(self, seed: int) -> None:
        ...

    def poll(self, t_s: float) -> list:
        """Measurements (with ``t_capture_s`` and ``pos_m``) that have arrived by ``t_s``, in capture order."""
        ...


class OracleSensor:
    """The world's own target channel at ``rate_hz``, each measurement delivered ``latency_ms`` after capture.

    Args:
        world: anything with ``measure_target()`` (the ``World`` protocol).
        rate_hz: capture rate, Hz (> 0).
        latency_ms: capture-to-arrival delay, ms (>= 0).
        dt_s: the control period the sensor is polled at, s (captures fall on its ticks).
    """

    def __init__(self, world: World, rate_hz: float = 100.0, latency_ms: float = 0.0, dt_s: float = 0.001) -> None:
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"perception rate_hz must be > 0, got {rate_hz!r}")
        if not (np.isfinite(latency_ms) and latency_ms >= 0):
            raise ValueError(f"perception latency_ms must be >= 0, got {latency_ms!r}")
        self.world = world
        self.rate_hz = float(rate_hz)
        self.latency_s = float(latency_ms) / 1000.0
        self._every = max(1, int(round(1.0 / (rate_hz * dt_s))))
        self._dt = float(dt_s)
        self._queue: deque[Measurement] = deque()
        self._k = 0
        self.captured = 0
        self.missed = 0

    def reset(self, seed: int) -> None:
        self._queue.clear()
        self._k = 0
        self.captured = self.missed = 0

    def poll(self, t_s: float) -> list[Measurement]:
        if self._k % self._every == 0:
            z = self.world.measure_target()
            self.captured += 1
            self.missed += z is None
            self._queue.append(Measurement(t_s, t_s + self.latency_s, None if z is None else np.asarray(z, dtype=float)))
        self._k += 1
        if not self._queue or self._queue[0].t_arrival_s > t_s + 0.5 * self._dt:
            return []  # most ticks: nothing has arrived
        out = []
        while self._queue and self._queue[0].t_arrival_s <= t_s + 0.5 * self._dt:
            out.append(self._queue.popleft())
        return out

    @property
    def stats(self) -> dict:
        return {"frames": self.captured, "missed": self.missed}
