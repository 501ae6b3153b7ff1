"""Fault injectors: one small wrapper per fault, built fresh per episode from a :class:`FaultSpec`.

Each fault wraps one part of the stack and leaves everything else untouched:

- the chunk source (:class:`FaultySource`): it raises, builds a NaN chunk, answers garbage tokens, answers a
  chunk that starts 25 cm away, falls silent, or answers late;
- the world's perception (:class:`FaultyPerception`): dropped, frozen, outlier or non-finite measurements;
- the world itself (:class:`MovedTarget`): the instructed ball is moved (its MuJoCo mocap body, so the camera,
  the measurements and the log all see it) out of reach, or to the edge of the workspace;
- the controller's solvers (:func:`_qp_fail_burst`, :func:`_mpc_late`): the real, counted fallback paths are
  forced for a while;
- the wire (``wire_*``, ``scenarios.faults.wire``): the source served over openpi's protocol on 127.0.0.1, the
  server raising (an error frame), slow past the client's timeout, answering wrong shapes or NaN, or dying and
  coming back;
- the command link (:class:`DroppedTicks`): a :class:`~mmact_ctrl.loop.CommandLink` that drops ticks;
- the initial state (``start_with_velocity``).

Wrappers delegate every other attribute to the wrapped object (``__getattr__``). :func:`inject` builds the
wrappers of one fault for one episode and returns an :class:`Injection` (use it as a context manager: patches
of the controller's solvers are removed on exit); :func:`run_fault_episode` runs one episode under a fault.

The registry :data:`FAULTS` maps each public fault name to its :class:`Fault`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from mmact_ctrl.chunk import ActionChunk

#: default onset of every fault, s.
DEFAULT_ONSET_S = 1.5
#: default length of a windowed fault, s.
DEFAULT_WINDOW_S = 1.5
#: the offset of ``splice_offset``'s chunks, m (along +x).
SPLICE_OFFSET_M = 0.25
#: where ``unreachable_target`` puts the instructed ball: 1.3 m in front of the base, 0.3 m high (the Panda
#: reaches ~0.855 m from its shoulder).
UNREACHABLE_POS_M = (1.3, 0.0, 0.3)
#: the Panda's shoulder (joint 2 axis) above its base, m.
SHOULDER_POS_M = (0.0, 0.0, 0.333)
#: where ``near_singularity`` puts the ball: straight out from the shoulder, 0.85 m away (the arm stretched).
NEAR_SINGULAR_POS_M = (0.85, 0.0, 0.333)
#: ``start_with_velocity``: joint velocities at the start (0.6 rad/s on joints 1, 2, 4, 0-based, alternating).
START_DQ_RAD_S = (0.0, 0.6, -0.6, 0.0, 0.6, 0.0, 0.0)
#: ``garbage_tokens``: an action token id far outside any vocabulary.
GARBAGE_TOKEN = 10**9

_EPS_S = 1e-9


@dataclass(frozen=True)
class FaultSpec:
    """One fault of one episode.

    Attributes:
        name: a key of :data:`FAULTS`.
        t_fault_s: onset, s of simulated time.
        duration_s: length of the fault window, s (None: the fault's own default: 1.5 s for windowed faults,
            the tick count of the tick faults, the given silence, to the end of the episode for the moved
            targets).
    """

    name: str
    t_fault_s: float = DEFAULT_ONSET_S
    duration_s: float | None = None

    def __post_init__(self) -> None:
        if self.name not in FAULTS:
            raise ValueError(f"unknown fault {self.name!r}; expected one of {', '.join(FAULTS)}")
        if not (math.isfinite(self.t_fault_s) and self.t_fault_s >= 0):
            raise ValueError(f"t_fault_s must be a finite number >= 0, got {self.t_fault_s!r}")
        if self.duration_s is not None and not (self.duration_s >= 0):
            raise ValueError(f"duration_s must be >= 0 or None, got {self.duration_s!r}")

    @property
    def fault(self) -> "Fault":
        return FAULTS[self.name]

    def window_s(self, dt_s: float = 0.001) -> tuple[float, float]:
        """The fault window ``[start, end)`` in s (end may be inf)."""
        f = self.fault
        if f.name == "start_with_velocity":
            return 0.0, 0.0
        if self.duration_s is not None:
            d = float(self.duration_s)
        elif f.ticks is not None:
            d = f.ticks * dt_s
        else:
            d = f.duration_s
        return float(self.t_fault_s), float(self.t_fault_s) + d


@dataclass
class Injection:
    """The wrapped parts of one episode under one fault: pass ``world``, ``source``, ``link`` and
    ``initial_dq_rad_s`` to :func:`~mmact_ctrl.loop.run_episode`. ``applicable`` is False when the fault has
    nothing to act on in this configuration (``mpc_late`` without an MPC). ``close()`` (or leaving the
    ``with`` block) removes the patches made on the controller."""

    spec: FaultSpec
    world: Any
    source: Any
    window_s: tuple[float, float]
    link: Any = None
    initial_dq_rad_s: np.ndarray | None = None
    applicable: bool = True
    _undo: list[Callable[[], None]] = field(default_factory=list, repr=False)

    def close(self) -> None:
        while self._undo:
            self._undo.pop()()

    def __enter__(self) -> "Injection":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _in(window: tuple[float, float], t_s: float) -> bool:
    return window[0] - _EPS_S <= t_s < window[1] - _EPS_S


def _now(world) -> float:
    """The world's simulated time (the loop's ``t`` at the tick being computed)."""
    data = getattr(world, "data", None)
    if data is not None and hasattr(data, "time"):
        return float(data.time)
    return float(world.state().t_s)


# ---- chunk source ----------------------------------------------------------------------------------


class FaultySource:
    """A chunk source whose answers to observations in ``window`` are spoiled by ``behaviour``:

    ``raise`` (RuntimeError), ``nan`` (tries to build an ``ActionChunk`` with NaN waypoints: its constructor
    raises ValueError), ``tokens`` (out-of-range integer tokens, or float tokens), ``splice`` (waypoints offset
    by :data:`SPLICE_OFFSET_M`), ``silent`` (None: nothing arrives), ``late`` (``info["arrival_delay_s"]`` set
    to ``delay_s``). Observations outside the window get the wrapped source's answer unchanged."""

    def __init__(self, inner, behaviour: str, window: tuple[float, float], delay_s: float = 0.0) -> None:
        if behaviour not in ("raise", "nan", "tokens", "splice", "silent", "late"):
            raise ValueError(f"unknown source fault behaviour {behaviour!r}")
        self._inner = inner
        self._behaviour = behaviour
        self._window = window
        self._delay_s = float(delay_s)
        self.faulty_calls = 0

    def __getattr__(self, name: str):  # everything else is the wrapped source's
        return getattr(self._inner, name)

    @property
    def needs_image(self) -> bool:
        return self._inner.needs_image

    @property
    def declared_capabilities(self) -> frozenset[str]:
        """The wrapped source's (it inpaints only if that one does)."""
        from mmact_ctrl.sources.contract import capabilities

        return capabilities(self._inner)

    @property
    def chunk_dt_s(self) -> float:
        return self._inner.chunk_dt_s

    @property
    def action_token_range(self):
        return getattr(self._inner, "action_token_range", None)

    def plan(self, observation):
        return self._answer(observation, lambda: self._inner.plan(observation))

    def plan_inpaint(self, observation, known):
        return self._answer(observation, lambda: self._inner.plan_inpaint(observation, known))

    def _answer(self, observation, call):
        if not _in(self._window, observation.t0_s):
            return call()
        self.faulty_calls += 1
        b = self._behaviour
        if b == "raise":
            raise RuntimeError(f"injected fault: the chunk source crashed at t={observation.t0_s:.3f} s")
        if b == "silent":
            return None
        chunk = call()
        if chunk is None:
            return None
        if b == "nan":
            w = np.array(chunk.waypoints, dtype=np.float64)
            w[:, :3] = np.nan
            return ActionChunk(waypoints=w, dt_s=chunk.dt_s, t0_s=chunk.t0_s, tokens=chunk.tokens, info=chunk.info)
        if b == "tokens":
            shape = np.asarray(chunk.waypoints).shape
            if self.action_token_range is not None and self.faulty_calls % 2 == 1:
                tokens = np.full(shape, GARBAGE_TOKEN, dtype=np.int64)  # ids far outside the vocabulary
            else:
                tokens = np.full(shape, 0.5, dtype=np.float64)  # not integers at all
            return dataclasses.replace(chunk, tokens=tokens)
        if b == "splice":
            w = np.array(chunk.waypoints, dtype=np.float64)
            w[:, 0] += SPLICE_OFFSET_M
            return dataclasses.replace(chunk, waypoints=w)
        # late
        return dataclasses.replace(chunk, info={**chunk.info, "arrival_delay_s": self._delay_s})


# ---- perception --------------------------------------------------------------------------------------


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
        if not _in(self._window, _now(self._inner)):
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
        if _in(self._window, _now(w)):
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


# ---- the command link ----------------------------------------------------------------------------------


class DroppedTicks:
    """A :class:`~mmact_ctrl.loop.CommandLink` that drops ``n`` consecutive ticks from the first tick at or
    after ``t_fault_s`` (the robot re-applies the last torque it received)."""

    def __init__(self, n: int, t_fault_s: float) -> None:
        self.n = int(n)
        self.t_fault_s = float(t_fault_s)
        self.k0: int | None = None
        self.dropped = 0

    def delivered(self, k: int, t_s: float) -> bool:
        if self.k0 is None and t_s >= self.t_fault_s - _EPS_S:
            self.k0 = int(k)
        if self.k0 is not None and self.k0 <= k < self.k0 + self.n:
            self.dropped += 1
            return False
        return True


# ---- the registry --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Fault:
    """One entry of :data:`FAULTS`.

    Attributes:
        name: public name.
        kind: ``baseline``, ``source``, ``perception``, ``controller``, ``link``, ``world``.
        description: one line for reports.
        build: ``build(spec, world, source, controller, injection)`` fills in the injection.
        duration_s: default window length, s (inf: to the end of the episode).
        ticks: tick faults: the window is this many control periods.
        unreachable: the target cannot be reached during the fault (no success or recovery is expected).
    """

    name: str
    kind: str
    description: str
    build: Callable[..., None]
    duration_s: float = DEFAULT_WINDOW_S
    ticks: int | None = None
    unreachable: bool = False


def _nothing(spec, world, source, controller, inj: Injection) -> None:
    pass


def _source_fault(behaviour: str):
    def build(spec, world, source, controller, inj: Injection) -> None:
        delay = 10.0 * controller.config.latency_ms / 1000.0 if behaviour == "late" else 0.0
        inj.source = FaultySource(source, behaviour, inj.window_s, delay_s=delay)

    return build


def _wire_fault(behaviour: str):
    """The source served over openpi's protocol on 127.0.0.1 with the wire failing in the window
    (``scenarios.faults.wire``); the server stops when the injection is closed."""

    def build(spec, world, source, controller, inj: Injection) -> None:
        from scenarios.faults.wire import WireServed

        served = WireServed(source, behaviour, inj.window_s, scene={"n_objects": int(getattr(world, "n_objects", 2))})
        inj.source = served
        inj._undo.append(served.close)

    return build


def _perception_fault(behaviour: str):
    def build(spec, world, source, controller, inj: Injection) -> None:
        inj.world = FaultyPerception(world, behaviour, inj.window_s)

    return build


def _moved_target(pos_m):
    def build(spec, world, source, controller, inj: Injection) -> None:
        if not len(getattr(world, "_mocap", ())):  # a contact task's object is physical, not a mocap ball: n/a
            inj.applicable = False
            return
        inj.world = MovedTarget(world, pos_m, inj.window_s)

    return build


def _dropped_ticks(n: int):
    def build(spec, world, source, controller, inj: Injection) -> None:
        start, end = inj.window_s
        ticks = int(round((end - start) / controller.config.dt_s)) if spec.duration_s is not None else n
        inj.link = DroppedTicks(ticks, start)

    return build


def _start_with_velocity(spec, world, source, controller, inj: Injection) -> None:
    inj.initial_dq_rad_s = np.array(START_DQ_RAD_S, dtype=np.float64)


def _qp_fail_burst(spec, world, source, controller, inj: Injection) -> None:
    """For the ticks of the window (50 from the onset) the QP's solve is its real, counted fallback."""
    qp = controller.qp
    start, end = inj.window_s
    n_ticks = int(round((end - start) / controller.config.dt_s))
    solve = qp.solve  # the bound method of the class
    done = [0]

    def faulty_solve(terms, q_rad, dq_rad_s, ref):
        if done[0] < n_ticks and _now(world) >= start - _EPS_S:
            done[0] += 1
            return qp.fallback(terms, q_rad, dq_rad_s)
        return solve(terms, q_rad, dq_rad_s, ref)

    qp.solve = faulty_solve
    inj._undo.append(lambda: qp.__dict__.pop("solve", None))


def _mpc_late(spec, world, source, controller, inj: Injection) -> None:
    """In the window every MPC solve is late: counted in ``mpc.late``, answered by the real fallback (the last
    plan re-timed). Not applicable without an MPC."""
    mpc = controller.mpc
    if mpc is None:
        inj.applicable = False
        return
    solve = mpc.solve
    window = inj.window_s

    def faulty_solve(t_s, q_rad, dq_rad_s, ee_pos_m, jacobian_6x7, pos_ref_m, rotvec_err_ref_rad=None):
        if not _in(window, float(t_s)):
            return solve(t_s, q_rad, dq_rad_s, ee_pos_m, jacobian_6x7, pos_ref_m, rotvec_err_ref_rad)
        t_start = time.perf_counter()
        mpc.solves += 1
        mpc.late += 1
        return mpc._fallback(float(t_s), np.asarray(q_rad, dtype=np.float64), np.asarray(dq_rad_s, dtype=np.float64),
                             np.asarray(ee_pos_m, dtype=np.float64), np.asarray(jacobian_6x7, dtype=np.float64), t_start)

    mpc.solve = faulty_solve
    inj._undo.append(lambda: mpc.__dict__.pop("solve", None))


def _registry() -> dict[str, Fault]:
    faults = [
        Fault("none", "baseline", "no fault (baseline)", _nothing, duration_s=0.0),
        Fault("source_raises", "source", "plan raises RuntimeError for 1.5 s", _source_fault("raise")),
        Fault("nan_chunk", "source", "the source builds a chunk with NaN waypoints (ActionChunk raises) for 1.5 s",
              _source_fault("nan")),
        Fault("garbage_tokens", "source", "chunks carry token ids 1e9 or float tokens for 1.5 s", _source_fault("tokens")),
        Fault("splice_offset", "source", f"chunks offset by {SPLICE_OFFSET_M} m for 1.5 s", _source_fault("splice")),
        Fault("source_silent_0.1s", "source", "the source answers nothing for 0.1 s", _source_fault("silent"),
              duration_s=0.1),
        Fault("source_silent_1.5s", "source", "the source answers nothing for 1.5 s", _source_fault("silent"),
              duration_s=1.5),
        Fault("source_silent_3s", "source", "the source answers nothing for 3 s", _source_fault("silent"),
              duration_s=3.0),
        Fault("latency_spike_10x", "source", "chunks arrive 10x the configured latency late for 1.5 s",
              _source_fault("late")),
        Fault("perception_dropout_50", "perception", "half the measurements missing for 1.5 s",
              _perception_fault("dropout")),
        Fault("perception_frozen", "perception", "the measurement frozen (bit-identical) for 1.5 s",
              _perception_fault("frozen")),
        Fault("perception_outlier", "perception", "10 % of the measurements 10 sigma off for 1.5 s",
              _perception_fault("outlier")),
        Fault("perception_nan", "perception", "every 5th measurement NaN, every 7th inf for 1.5 s",
              _perception_fault("nan")),
        Fault("qp_fail_burst", "controller", "50 ticks of QP fallback", _qp_fail_burst, ticks=50),
        Fault("mpc_late", "controller", "every MPC solve late for 0.5 s (hybrid only)", _mpc_late, duration_s=0.5),
        *[Fault(f"missed_ticks_{n}", "link", f"{n} consecutive ticks not delivered", _dropped_ticks(n), ticks=n)
          for n in (1, 5, 19, 20)],
        Fault("start_with_velocity", "world", "the arm starts moving (0.6 rad/s on joints 1, 2, 4)",
              _start_with_velocity, duration_s=0.0),
        Fault("unreachable_target", "world", "the ball moves 1.3 m in front of the base at the onset",
              _moved_target(UNREACHABLE_POS_M), duration_s=math.inf, unreachable=True),
        Fault("near_singularity", "world", "the ball moves 0.85 m straight out from the shoulder at the onset",
              _moved_target(NEAR_SINGULAR_POS_M), duration_s=math.inf),
        Fault("wire_error_frame", "wire", "the policy server raises: an error (text) frame, connection closed, for 1.5 s",
              _wire_fault("error_frame")),
        Fault("wire_slow", "wire", "the policy server answers after the client's request timeout for 1.5 s",
              _wire_fault("slow")),
        Fault("wire_bad_shape", "wire", "the policy server answers actions of the wrong shape for 1.5 s",
              _wire_fault("bad_shape")),
        Fault("wire_nan", "wire", "the policy server answers NaN actions for 1.5 s", _wire_fault("nan")),
        Fault("wire_server_dies", "wire", "the policy server stops at the onset (port closed), back after 1.5 s",
              _wire_fault("dies")),
    ]
    return {f.name: f for f in faults}


#: every fault by its public name.
FAULTS: dict[str, Fault] = _registry()


def inject(spec: FaultSpec, world, source, controller) -> Injection:
    """The wrapped world, source, link and initial velocity of one episode under ``spec`` (wrappers built fresh;
    solver patches are made on ``controller`` and removed by ``Injection.close()``)."""
    inj = Injection(spec=spec, world=world, source=source, window_s=spec.window_s(controller.config.dt_s))
    try:
        spec.fault.build(spec, world, source, controller, inj)
    except Exception:
        inj.close()
        raise
    return inj


def run_fault_episode(spec: FaultSpec, world, source, controller, seed: int, **kwargs):
    """One episode of ``controller.config.duration_s`` under the fault; returns ``(log, injection)``."""
    from mmact_ctrl.loop import run_episode

    with inject(spec, world, source, controller) as inj:
        log = run_episode(inj.world, inj.source, controller, seed, link=inj.link,
                          initial_dq_rad_s=inj.initial_dq_rad_s, **kwargs)
    return log, inj
