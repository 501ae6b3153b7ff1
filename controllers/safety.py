"""One definition of "a torque command the Panda accepts", checked on every 1 kHz tick.

A Drake-``Simulator``-monitor-style check of the command *actually sent* (after every filter and
clamp), not of what a controller meant to send. The conditions come from Franka's
``control_parameters`` specification (docs "Control parameters specifications", limit table;
libfranka ``rate_limiting.h``):

Necessary in torque control (breaking them aborts the motion on a real arm):

- ``nonfinite``: every value of the torque command is finite. libfranka refuses a NaN or +-inf
  torque before it is sent (``franka::Torques`` throws ``std::invalid_argument``). A non-finite
  commanded joint acceleration counts here too: the torque it was computed from is meaningless.
- ``torque_rate``: ``|tau - tau_last| / dt <= dtau_max`` (1000 N m/s on every joint, i.e. 1 N m per
  1 ms tick), ``tau_last`` being the last torque the robot *received*; the robot aborts a motion that
  breaks it with ``controller_torque_discontinuity``.

Recommended effort limit of the controller requirements:

- ``torque``: ``|tau| <= tau_max`` (87 N m joints 1-4, 12 N m joints 5-7).

Necessary conditions of the joint-space motion generator (the motion this torque controller
produces must satisfy them to be replayable by Franka's own generators; a real arm reflexes on the
measured position and velocity ones with ``joint_position_limits_violation`` /
``joint_velocity_violation``):

- ``position``: ``q_min <= q <= q_max`` (measured);
- ``velocity``: ``|dq| <= dq_max`` (measured);
- ``accel``: ``|ddq_cmd| <= ddq_max`` (the acceleration the command asks for);
- ``jerk``: ``|ddq_cmd - ddq_cmd_last| / dt <= dddq_max`` (backward Euler over one tick);
- ``tcp_speed``: ``||v_tcp|| <= 1.7 m/s``, the Panda datasheet's end-effector speed (stricter than
  the 1.87 m/s translational limit of the Cartesian motion-generator table).

The joint limits come from :class:`controllers.robot_description.JointLimits`; the torque rate and
the TCP speed from :class:`CommandLimits`. A value exactly at or within ``1e-9`` (relative to the
limit) of a limit passes; one beyond that is flagged. Measured values (``q``, ``dq``, ``v_tcp``) that
are not finite cannot be shown inside their limit and are flagged under their own kind.

``SafetyMonitor.check`` is one call of a compiled kernel (:func:`check_tick`) over arrays packed once
in ``__init__``; it allocates nothing per tick. This module imports numpy, numba and
``controllers.robot_description`` only, so it can watch a real arm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
from numba import njit

from controllers.layout import packed_layout
from controllers.robot_description import JointLimits

KINDS: tuple[str, ...] = ("nonfinite", "torque_rate", "torque", "position", "velocity", "accel", "jerk", "tcp_speed")
#: bit of each kind in the mask returned by :meth:`SafetyMonitor.check` (read-only).
BITS = MappingProxyType({k: 1 << i for i, k in enumerate(KINDS)})
NONFINITE, TORQUE_RATE, TORQUE, POSITION, VELOCITY, ACCEL, JERK, TCP_SPEED = (1 << i for i in range(len(KINDS)))
#: relative tolerance of every limit: ``|x| <= L (1 + LIMIT_RTOL)`` passes.
LIMIT_RTOL = 1e-9

N_JOINTS = 7

# Layout of the packed limit vector ``lim`` read by :func:`check_tick` (thresholds, tolerance included); numba freezes
# the module-level ints below as constants.
LIMITS_LAYOUT, N_LIM = packed_layout(("tau", 7), ("q_lo", 7), ("q_hi", 7), ("v", 7), ("a", 7), ("j", 7), ("dtau", 1),
                                     ("tcp", 1), ("dt", 1))
_TAU, _Q_LO, _Q_HI, _V, _A, _J, _DTAU, _TCP, _DT = LIMITS_LAYOUT.values()
# Layout of the state vector: last finite torque received, last finite ddq command, largest torque rate.
STATE_LAYOUT, N_STATE = packed_layout(("tau", 7), ("ddq", 7), ("rate_max", 1))
_S_TAU, _S_DDQ, _S_RATE_MAX = STATE_LAYOUT.values()
# Layout of the integer statistics: ticks flagged per kind, then ticks checked, ticks with any violation.
_N_TICKS, _N_VIOL = len(KINDS), len(KINDS) + 1
N_STATS = len(KINDS) + 2


def _positive(name: str, value: float) -> None:
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value) and value > 0):
        raise ValueError(f"CommandLimits.{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True)
class CommandLimits:
    """The Panda's conditions on a torque command (units in names).

    Attributes:
        dt_s: control period, s (the torque rate and jerk are differences over one period).
        joint: per-joint position, velocity, acceleration, jerk and effort limits.
        dtau_max_nm_s: torque rate limit, N m/s, every joint (libfranka ``kMaxTorqueRate``).
        tcp_speed_max_m_s: TCP linear speed limit, m/s.

    Raises ``ValueError`` naming the field for a non-positive or non-finite period or limit, a joint
    limit that does not have 7 entries, or ``q_min_rad >= q_max_rad`` on some joint.
    """

    dt_s: float = 0.001
    joint: JointLimits = field(default_factory=JointLimits)
    dtau_max_nm_s: float = 1000.0
    tcp_speed_max_m_s: float = 1.7

    def __post_init__(self) -> None:
        _positive("dt_s", self.dt_s)
        _positive("dtau_max_nm_s", self.dtau_max_nm_s)
        _positive("tcp_speed_max_m_s", self.tcp_speed_max_m_s)
        if not isinstance(self.joint, JointLimits):
            raise ValueError(f"CommandLimits.joint must be a JointLimits, got {type(self.joint).__name__}")
        for name in ("q_min_rad", "q_max_rad", "v_max_rad_s", "a_max_rad_s2", "j_max_rad_s3", "tau_max_nm"):
            try:
                v = np.asarray(getattr(self.joint, name), dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"CommandLimits.joint.{name} must be 7 numbers: {exc}") from None
            if v.shape != (N_JOINTS,):
                raise ValueError(f"CommandLimits.joint.{name} must have {N_JOINTS} entries, got shape {v.shape}")
            for i, x in enumerate(v):
                if not math.isfinite(x) or (not name.startswith("q_") and x <= 0):
                    need = "finite" if name.startswith("q_") else "finite and > 0"
                    raise ValueError(f"CommandLimits.joint.{name}[{i}] (joint {i + 1}) must be {need}, got {x!r}")
        lo, hi = np.asarray(self.joint.q_min_rad, float), np.asarray(self.joint.q_max_rad, float)
        for i in np.flatnonzero(lo >= hi):
            raise ValueError(
                f"CommandLimits.joint.q_min_rad[{i}] = {lo[i]!r} must be < q_max_rad[{i}] = {hi[i]!r} (joint {i + 1})"
            )

    def packed(self) -> np.ndarray:
        """The flat limit vector :func:`check_tick` reads, tolerance folded into each threshold."""
        j = self.joint.arrays()
        up = 1.0 + LIMIT_RTOL
        p = np.empty(N_LIM)
        p[_TAU:_TAU + 7] = j["tau_max_nm"] * up
        p[_Q_LO:_Q_LO + 7] = j["q_min_rad"] - LIMIT_RTOL * np.abs(j["q_min_rad"])
        p[_Q_HI:_Q_HI + 7] = j["q_max_rad"] + LIMIT_RTOL * np.abs(j["q_max_rad"])
        p[_V:_V + 7] = j["v_max_rad_s"] * up
        p[_A:_A + 7] = j["a_max_rad_s2"] * up
        p[_J:_J + 7] = j["j_max_rad_s3"] * up
        p[_DTAU] = self.dtau_max_nm_s * up
        p[_TCP] = self.tcp_speed_max_m_s * up
        p[_DT] = self.dt_s
        return p


# Bits, spelled out for the kernel (numba freezes module-level ints as constants).
_B_NONFINITE, _B_RATE, _B_TORQUE, _B_POS, _B_VEL, _B_ACC, _B_JERK, _B_TCP = 1, 2, 4, 8, 16, 32, 64, 128
assert (_B_NONFINITE, _B_RATE, _B_TORQUE, _B_POS, _B_VEL, _B_ACC, _B_JERK, _B_TCP) == tuple(BITS.values())

_SIG = "int64(float64[:], float64[:], float64[:], float64[:], float64[:], float64[::1], float64[::1], int64[::1])"


@njit(_SIG, cache=True, nogil=True)
def check_tick(tau, q, dq, ddq, v_tcp, lim, state, stats):
    """One tick of :class:`SafetyMonitor`: returns the violation bitmask (bit ``i`` = ``KINDS[i]``),
    updates ``state`` (last finite torque and ddq command, largest torque rate) and ``stats``.

    A non-finite ``tau`` (``ddq``) is flagged ``nonfinite`` only: its finite entries are still held to
    the effort (acceleration) limit, but the rate (jerk) check is skipped and the stored reference is
    kept, since the robot never received that command. Comparisons are written ``not (x <= limit)`` so
    a NaN in the measured state is flagged under its own kind."""
    if tau.shape[0] != 7 or q.shape[0] != 7 or dq.shape[0] != 7 or ddq.shape[0] != 7 or v_tcp.shape[0] != 3:
        raise ValueError("check: tau, q, dq, ddq_cmd must have shape (7,), tcp_vel shape (3,)")
    dt = lim[_DT]
    mask = 0
    tau_ok = True
    ddq_ok = True
    for i in range(7):
        t = tau[i]
        if not math.isfinite(t):
            tau_ok = False
        elif abs(t) > lim[_TAU + i]:
            mask |= _B_TORQUE
        a = ddq[i]
        if not math.isfinite(a):
            ddq_ok = False
        elif abs(a) > lim[_A + i]:
            mask |= _B_ACC
        if not (lim[_Q_LO + i] <= q[i] <= lim[_Q_HI + i]):
            mask |= _B_POS
        if not (abs(dq[i]) <= lim[_V + i]):
            mask |= _B_VEL
    if not (tau_ok and ddq_ok):
        mask |= _B_NONFINITE
    if tau_ok:
        rate_max = state[_S_RATE_MAX]
        for i in range(7):
            r = abs(tau[i] - state[_S_TAU + i]) / dt
            if r > rate_max:
                rate_max = r
            if r > lim[_DTAU]:
                mask |= _B_RATE
            state[_S_TAU + i] = tau[i]
        state[_S_RATE_MAX] = rate_max
    if ddq_ok:
        for i in range(7):
            if abs(ddq[i] - state[_S_DDQ + i]) / dt > lim[_J + i]:
                mask |= _B_JERK
            state[_S_DDQ + i] = ddq[i]
    speed = math.sqrt(v_tcp[0] * v_tcp[0] + v_tcp[1] * v_tcp[1] + v_tcp[2] * v_tcp[2])
    if not (speed <= lim[_TCP]):
        mask |= _B_TCP
    stats[_N_TICKS] += 1
    if mask != 0:
        stats[_N_VIOL] += 1
        for k in range(8):
            if mask & (1 << k):
                stats[k] += 1
    return mask


def describe(mask: int) -> list[str]:
    """Kind names of a bitmask from :meth:`SafetyMonitor.check`, in :data:`KINDS` order."""
    mask = int(mask)
    if mask < 0 or mask >> len(KINDS):
        raise ValueError(f"mask {mask:#x} has bits outside the {len(KINDS)} kinds {KINDS}")
    return [k for i, k in enumerate(KINDS) if mask >> i & 1]


_F64 = np.dtype(np.float64)
_ARGS = ((7, "tau_nm"), (7, "q_rad"), (7, "dq_rad_s"), (7, "ddq_cmd_rad_s2"), (3, "tcp_vel_m_s"))


def _as_vec(x, n: int, name: str) -> np.ndarray:
    a = np.ascontiguousarray(x, dtype=np.float64)
    if a.shape != (n,):
        raise ValueError(f"SafetyMonitor.check: {name} must have shape ({n},), got {a.shape}")
    return a


class SafetyMonitor:
    """Drake-Simulator-monitor-style per-tick check of the command actually sent.

    Call :meth:`reset` at the start of each episode/motion with the torque the robot applies before
    the first command (the first command's rate is measured against it), then :meth:`check` once per
    control tick with the torque the robot receives that tick. Each call returns a bitmask over
    :data:`KINDS` (0: the Panda accepts the command) and counts the flagged ticks per kind; the
    conditions and where they come from are in the module docstring.

    ``check`` hands float64 1-d arrays (any stride) straight to one compiled call, allocating nothing
    (about 1 us); other array-likes (lists, float32, int) are converted first (a few us more).
    Wrong shapes raise ``ValueError`` naming the argument, before any state changes. Not
    thread-safe: one monitor per control loop.
    """

    describe = staticmethod(describe)

    def __init__(self, limits: CommandLimits = CommandLimits()) -> None:
        if not isinstance(limits, CommandLimits):
            raise TypeError(f"limits must be a CommandLimits, got {type(limits).__name__}")
        self.limits = limits
        self._lim = limits.packed()
        self._state = np.zeros(N_STATE)
        self._stats = np.zeros(N_STATS, dtype=np.int64)
        self._last_mask = 0
        self._armed = False

    def reset(self, tau_start_nm, ddq_start_rad_s2=None) -> None:
        """Start of an episode/motion: forget the statistics, take ``tau_start_nm`` (7,) as the last
        torque the robot received and ``ddq_start_rad_s2`` (7,, default zeros) as the last commanded
        acceleration. Both must be finite."""
        tau0 = _as_vec(tau_start_nm, N_JOINTS, "tau_start_nm")
        if ddq_start_rad_s2 is None:
            ddq0 = np.zeros(N_JOINTS)
        else:
            ddq0 = _as_vec(ddq_start_rad_s2, N_JOINTS, "ddq_start_rad_s2")
        for name, a in (("tau_start_nm", tau0), ("ddq_start_rad_s2", ddq0)):
            if not np.all(np.isfinite(a)):
                raise ValueError(f"SafetyMonitor.reset: {name} must be finite, got {a}")
        self._state[_S_TAU:_S_TAU + 7] = tau0
        self._state[_S_DDQ:_S_DDQ + 7] = ddq0
        self._state[_S_RATE_MAX] = 0.0
        self._stats[:] = 0
        self._last_mask = 0
        self._armed = True

    def check(self, tau_nm, q_rad, dq_rad_s, ddq_cmd_rad_s2, tcp_vel_m_s) -> int:
        """One tick: ``tau_nm`` (7,) the torque the robot receives, ``q_rad``/``dq_rad_s`` (7,) the
        measured state, ``ddq_cmd_rad_s2`` (7,) the commanded joint acceleration, ``tcp_vel_m_s`` (3,)
        the TCP linear velocity. Returns the violation bitmask (bit ``i`` set <=> ``KINDS[i]``)."""
        if not self._armed:
            raise RuntimeError("SafetyMonitor.check before reset(tau_start_nm): the first torque rate has no reference")
        f = _F64
        try:  # float64 arrays go straight to the kernel (it checks ndim and shapes); the rest are converted
            fast = tau_nm.dtype is f and q_rad.dtype is f and dq_rad_s.dtype is f and ddq_cmd_rad_s2.dtype is f
            fast = fast and tcp_vel_m_s.dtype is f
        except AttributeError:
            fast = False
        if not fast:
            tau_nm, q_rad = _as_vec(tau_nm, 7, "tau_nm"), _as_vec(q_rad, 7, "q_rad")
            dq_rad_s, ddq_cmd_rad_s2 = _as_vec(dq_rad_s, 7, "dq_rad_s"), _as_vec(ddq_cmd_rad_s2, 7, "ddq_cmd_rad_s2")
            tcp_vel_m_s = _as_vec(tcp_vel_m_s, 3, "tcp_vel_m_s")
        try:
            m = check_tick(tau_nm, q_rad, dq_rad_s, ddq_cmd_rad_s2, tcp_vel_m_s, self._lim, self._state, self._stats)
        except (TypeError, ValueError):  # wrong ndim or shape: say which argument
            for x, (n, name) in zip((tau_nm, q_rad, dq_rad_s, ddq_cmd_rad_s2, tcp_vel_m_s), _ARGS):
                _as_vec(x, n, name)
            raise
        self._last_mask = m
        return m

    @property
    def counts(self) -> dict[str, int]:
        """Ticks flagged, per kind (a tick counts once per kind, however many joints break it)."""
        return {k: int(self._stats[i]) for i, k in enumerate(KINDS)}

    @property
    def ticks(self) -> int:
        """Ticks checked since :meth:`reset`."""
        return int(self._stats[_N_TICKS])

    @property
    def violations(self) -> int:
        """Ticks with any violation (mask != 0) since :meth:`reset`."""
        return int(self._stats[_N_VIOL])

    @property
    def torque_rate_max_nm_s(self) -> float:
        """Largest ``|tau - tau_last| / dt_s`` seen since :meth:`reset` over finite torques (each measured
        against the last finite torque received, the first against the reset torque); 0.0 before any."""
        return float(self._state[_S_RATE_MAX])

    @property
    def last_mask(self) -> int:
        """Bitmask of the last :meth:`check` (0 before any)."""
        return self._last_mask
