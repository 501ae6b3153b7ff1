"""Faults of the world: :class:`FaultyPerception` (dropped, frozen, outlier or non-finite measurements),
:class:`MovedTarget` (the instructed ball moved out of reach or to the edge of the workspace), and the builders of
the ``perception`` and ``world`` faults of the registry (``start_with_velocity`` among them)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from scenarios.faults.clock import in_window, sim_time_s

if TYPE_CHECKING:
    from scenarios.faults.spec import Injection

#: where ``unreachable_target`` puts the instructed ball: 1.3 m in front of the base, 0.3 m high (the Panda
#: reaches ~0.855 m from its shoulder).
UNREACHABLE_POS_M = (1.3, 0.0, 0.3)
#: the Panda's shoulder (joint 2 axis) above its base, m.
SHOULDER_POS_M = (0.0, 0.0, 0.333)
#: where ``near_singularity`` puts the ball: straight out from the shoulder, 0.85 m away (the arm stretched).
NEAR_SINGULAR_POS_M = (0.85, 0.0, 0.333)
#: ``start_with_velocity``: joint velocities at the start (0.6 rad/s on joints 1, 2, 4, 0-based, alternating).
START_DQ_RAD_S = (0.0, 0.6, -0.6, 0.0, 0.6, 0.0, 0.0)


class _WorldWrapper:
    """Delegates everything to the wrapped world; subclasses override what their fault changes."""

    def __init__(self, inner) -> None:
        self._inner = inner

    def __getattr__(self, name: str):
        return getattr(self._inner, name)

    def reset(self, seed: int, *args, **kwargs):
        return self._inner.reset(seed, *args, **kwargs)

    def step(self, tau_nm, gripper_m) -> None:
        self._inner.step(tau_nm, gripper_m)

    def state(self):
        return self._inner.state()

    def target_pos_m(self):
        return self._inner.target_pos_m()

    def measure_target(self):
        return self._inner.measure_target()

    def objects_pos_m(self):
        return self._inner.objects_pos_m()

    def render(self):
        return self._inner.render()


class FaultyPerception(_WorldWrapper):
    """``measure_target`` spoiled in ``window``: ``dropout`` (None with probability 0.5, on top of the world's
    own), ``frozen`` (the last value before the onset, bit-identical), ``outlier`` (10 % of the measurements are
    the truth + a 10-sigma offset in a random direction, sigma = the innovation's standard deviation, about
    1.25 x the world's ``noise_m`` (at least 2 mm) for the filter in steady state: 25 mm at the default noise), ``nan``
    (every 5th measurement of the window is NaN, every 7th +inf). Its random draws are seeded per episode by
    ``reset(seed)``."""

    def __init__(self, inner, behaviour: str, window: tuple[float, float]) -> None:
        if behaviour not in ("dropout", "frozen", "outlier", "nan"):
            raise ValueError(f"unknown perception fault behaviour {behaviour!r}")
        super().__init__(inner)
        self._behaviour = behaviour
        self._window = window
        self._rng = np.random.default_rng(0)
        self._last: np.ndarray | None = None
        self._n_window = 0
        self.faulty_measurements = 0

    def reset(self, seed: int, *args, **kwargs):
        self._rng = np.random.default_rng([int(seed), 0xFA17])
        self._last = None
        self._n_window = 0
        self.faulty_measurements = 0
        return self._inner.reset(seed, *args, **kwargs)

    def measure_target(self):
        z = self._inner.measure_target()  # always drawn: the world's own noise stream stays the same
        if not in_window(self._window, sim_time_s(self._inner)):
            if z is not None:
                self._last = np.array(z, dtype=np.float64, copy=True)
            return z
        self._n_window += 1
        b = self._behaviour
        if b == "dropout":
            if z is not None and self._rng.uniform() < 0.5:
                self.faulty_measurements += 1
                return None
            return z
        if b == "frozen":
            if self._last is None:
                return z
            self.faulty_measurements += 1
            return self._last.copy()
        if b == "outlier":
            if z is None or self._rng.uniform() >= 0.1:
                return z
            sigma = max(float(getattr(self._inner, "noise_m", 0.0)), 0.002)
            u = self._rng.normal(size=3)
            u /= np.linalg.norm(u)
            self.faulty_measurements += 1
            return np.asarray(self._inner.target_pos_m(), dtype=np.float64) + 12.5 * sigma * u
        # nan
        if self._n_window % 5 == 0:
            self.faulty_measurements += 1
            return np.full(3, np.nan)
        if self._n_window % 7 == 0:
            self.faulty_measurements += 1
            return np.full(3, np.inf)
        return z


# ---- the world ---------------------------------------------------------------------------------------


class MovedTarget(_WorldWrapper):
    """From the onset the instructed ball sits at ``pos_m``: its mocap body is written after every step (and
    when the onset is 0, at reset), so rendering, ``target_pos_m``, ``measure_target`` and ``objects_pos_m``
    all see it."""

    def __init__(self, inner, pos_m, window: tuple[float, float]) -> None:
        super().__init__(inner)
        self._pos = np.asarray(pos_m, dtype=np.float64).copy()
        self._window = window
        self.moved = False

    def _place(self) -> None:
        w = self._inner
        if in_window(self._window, sim_time_s(w)):
            mocap = w.data.mocap_pos
            i = w._mocap[w.target_index]
            if not np.array_equal(mocap[i], self._pos):
                mocap[i] = self._pos
                if hasattr(w, "_kinematics_stale"):  # the body's frame (what the camera shows) follows at next use
                    w._kinematics_stale = True
            self.moved = True

    def reset(self, seed: int, *args, **kwargs):
        self.moved = False
        state = self._inner.reset(seed, *args, **kwargs)
        self._place()
        return state

    def step(self, tau_nm, gripper_m) -> None:
        self._inner.step(tau_nm, gripper_m)
        self._place()

    def target_pos_m(self):
        self._place()
        return self._inner.target_pos_m()

    def measure_target(self):
        self._place()
        return self._inner.measure_target()

    def objects_pos_m(self):
        self._place()
        return self._inner.objects_pos_m()


# ---- builders of the registry -------------------------------------------------------------------------------


def perception_fault(behaviour: str):
    def build(spec, world, source, controller, inj: Injection) -> None:
        inj.world = FaultyPerception(world, behaviour, inj.window_s)

    return build


def moved_target(pos_m):
    def build(spec, world, source, controller, inj: Injection) -> None:
        if not len(getattr(world, "_mocap", ())):  # a contact task's object is physical, not a mocap ball: n/a
            inj.applicable = False
            return
        inj.world = MovedTarget(world, pos_m, inj.window_s)

    return build


def start_with_velocity(spec, world, source, controller, inj: Injection) -> None:
    inj.initial_dq_rad_s = np.array(START_DQ_RAD_S, dtype=np.float64)

