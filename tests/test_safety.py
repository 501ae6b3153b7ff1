"""controllers.safety: the per-tick check of "a command the Panda accepts".

In the spirit of libfranka's ``test/rate_limiting_tests.cpp`` and ``test/control_loop_tests.cpp``: each
condition held to hand-made sequences just inside (passes, counts unchanged) and just outside (flagged
with exactly that kind's bit), non-finite torques that must not corrupt the rate reference, and a plain
numpy reference of the whole check against the compiled kernel on random sequences near the limits.
"""

from __future__ import annotations

import ast
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from controllers.robot_description import HOME_Q_RAD, JointLimits
from controllers.safety import BITS, KINDS, CommandLimits, SafetyMonitor, describe

LIM = JointLimits().arrays()
DT = 0.001
TAU0 = np.array([0.3, -21.7, 0.65, 19.9, 0.71, 2.13, -0.04])  # gravity-like, not round: exercises rounding
Q0 = np.array(HOME_Q_RAD)
ZERO7 = np.zeros(7)
ZERO3 = np.zeros(3)
SNAN_BITS = 0x7FF0000000000001
EPS = 1e-6  # "just" inside/outside, far above the 1e-9 relative tolerance and far below any limit


def _snan() -> float:
    return np.array([SNAN_BITS], dtype=np.uint64).view(np.float64)[0]


def _with_bits(base: np.ndarray, j: int, bits: int) -> np.ndarray:
    """``base`` with entry ``j`` set to the float64 of ``bits`` (bit-exact: no float op touches it)."""
    raw = np.asarray(base, dtype=np.float64).copy().view(np.uint64)
    raw[j] = bits
    return raw.view(np.float64)


NONFINITE = {
    "qnan": lambda base, j: _with_bits(base, j, np.array([np.nan]).view(np.uint64)[0]),
    "snan": lambda base, j: _with_bits(base, j, SNAN_BITS),
    "+inf": lambda base, j: _with_bits(base, j, np.array([np.inf]).view(np.uint64)[0]),
    "-inf": lambda base, j: _with_bits(base, j, np.array([-np.inf]).view(np.uint64)[0]),
}


class Tick:
    """A monitor with a nominal state (home pose at rest, gravity-like torque) and one-argument overrides."""

    def __init__(self, tau_start=TAU0, ddq_start=None, limits=None):
        self.mon = SafetyMonitor(limits or CommandLimits())
        self.mon.reset(tau_start, ddq_start)
        self.tau = np.array(tau_start, dtype=float)
        self.ddq = ZERO7.copy() if ddq_start is None else np.array(ddq_start, dtype=float)

    def __call__(self, tau=None, q=None, dq=None, ddq=None, v=None) -> int:
        tau = self.tau if tau is None else tau
        ddq = self.ddq if ddq is None else ddq
        return self.mon.check(tau, Q0 if q is None else q, ZERO7 if dq is None else dq, ddq, ZERO3 if v is None else v)


def _counts_zero(mon) -> bool:
    return all(v == 0 for v in mon.counts.values())


def _step(base, j, delta):
    out = np.array(base, dtype=float)
    out[j] += delta
    return out


# ---------------------------------------------------------------- the nominal state passes


def test_nominal_state_passes():
    t = Tick()
    for _ in range(5):
        assert t() == 0
    assert t.mon.ticks == 5 and t.mon.violations == 0 and _counts_zero(t.mon)
    assert t.mon.torque_rate_max_nm_s == 0.0
    assert t.mon.last_mask == 0


def test_check_before_reset_raises():
    with pytest.raises(RuntimeError, match="reset"):
        SafetyMonitor().check(TAU0, Q0, ZERO7, ZERO7, ZERO3)


# ---------------------------------------------------------------- torque rate (necessary)


@pytest.mark.parametrize("j", range(7))
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_torque_rate_just_inside_passes_just_outside_flagged(j, sign):
    t = Tick()
    tau = TAU0.copy()
    for _ in range(3):  # a ramp of steps just under 1 N m per 1 ms tick
        tau = _step(tau, j, sign * (1.0 - EPS))
        assert t(tau=tau) == 0
    tau_exact = _step(tau, j, sign * 1.0)  # exactly at the limit (up to rounding of the sum)
    assert t(tau=tau_exact) == 0
    assert _counts_zero(t.mon) and t.mon.violations == 0
    assert t(tau=_step(tau_exact, j, sign * (1.0 + EPS))) == BITS["torque_rate"]
    assert t.mon.counts["torque_rate"] == 1 and t.mon.violations == 1 and t.mon.ticks == 5


def test_torque_rate_reference_is_the_last_torque_received_even_when_flagged():
    t = Tick()
    jump = _step(TAU0, 1, 3.0)
    assert t(tau=jump) == BITS["torque_rate"]
    assert t(tau=jump) == 0  # the robot received ``jump``: holding it is no step
    assert t(tau=TAU0) == BITS["torque_rate"]


def test_first_command_is_measured_against_the_reset_torque():
    t = Tick(tau_start=TAU0)
    assert t(tau=_step(TAU0, 3, 5.0)) == BITS["torque_rate"]
    assert t.mon.torque_rate_max_nm_s == pytest.approx(5.0 / DT, rel=1e-9)
    # the same command right after a reset at that torque is accepted
    t.mon.reset(_step(TAU0, 3, 5.0))
    assert t.mon.check(_step(TAU0, 3, 5.0), Q0, ZERO7, ZERO7, ZERO3) == 0
    # and a first command 5 N m from a zero reset torque is flagged, not silently measured against itself
    mon = SafetyMonitor()
    mon.reset(ZERO7)
    assert mon.check(_step(ZERO7, 6, -5.0), Q0, ZERO7, ZERO7, ZERO3) == BITS["torque_rate"]


def test_reset_clears_statistics_and_takes_the_new_references():
    t = Tick()
    t(tau=_step(TAU0, 0, 2.0), dq=np.full(7, 3.0))
    assert t.mon.violations == 1 and t.mon.torque_rate_max_nm_s > 0
    t.mon.reset(TAU0, np.full(7, 1.0))
    assert t.mon.ticks == 0 and t.mon.violations == 0 and _counts_zero(t.mon)
    assert t.mon.torque_rate_max_nm_s == 0.0 and t.mon.last_mask == 0
    assert t.mon.check(TAU0, Q0, ZERO7, np.full(7, 1.0), ZERO3) == 0  # jerk measured against ddq_start
    assert t.mon.check(TAU0, Q0, ZERO7, ZERO7, ZERO3) == 0  # 1 rad/s^2 in 1 ms = 1000 rad/s^3 < 3750
    with pytest.raises(ValueError, match="tau_start_nm"):
        t.mon.reset(_with_bits(TAU0, 2, SNAN_BITS))
    with pytest.raises(ValueError, match="ddq_start_rad_s2"):
        t.mon.reset(TAU0, np.full(7, np.inf))
    with pytest.raises(ValueError, match="tau_start_nm"):
        t.mon.reset(np.zeros(6))


def test_torque_rate_max_is_the_largest_step_over_dt():
    steps = [0.3, -0.7, 0.95, 0.2, 2.5, -0.1, -1.8, 0.0]
    t = Tick()
    tau, taus = TAU0.copy(), [TAU0.copy()]
    rng = np.random.default_rng(3)
    for s in steps:
        tau = tau + s * rng.uniform(0.2, 1.0, 7) * np.sign(rng.normal(size=7))
        tau[2] = taus[-1][2] + s  # one joint carries the exact step
        t(tau=tau)
        taus.append(tau.copy())
    expected = max(np.max(np.abs(b - a)) / DT for a, b in zip(taus, taus[1:]))
    assert t.mon.torque_rate_max_nm_s == pytest.approx(expected, rel=1e-12)
    assert t.mon.torque_rate_max_nm_s >= 2.5 / DT * (1 - 1e-12)
    # a non-finite tick in between counts for nothing; the next finite step is measured against the last finite
    before = t.mon.torque_rate_max_nm_s
    assert t(tau=NONFINITE["+inf"](tau, 4)) == BITS["nonfinite"]
    assert t.mon.torque_rate_max_nm_s == before
    assert t(tau=_step(tau, 5, 0.5)) == 0
    assert t.mon.torque_rate_max_nm_s == before


# ---------------------------------------------------------------- non-finite values (necessary)


@pytest.mark.parametrize("kind", list(NONFINITE))
@pytest.mark.parametrize("j", [0, 3, 6])
def test_nonfinite_torque_flagged_and_does_not_corrupt_the_rate_reference(kind, j):
    t = Tick()
    last = _step(TAU0, j, 0.9)
    assert t(tau=last) == 0
    bad = NONFINITE[kind](last, j)
    if kind == "snan":
        assert bad.view(np.uint64)[j] == SNAN_BITS and math.isnan(bad[j])
    assert not np.isfinite(bad[j])
    assert t(tau=bad) == BITS["nonfinite"]
    assert t(tau=bad) == BITS["nonfinite"]  # twice in a row: still only nonfinite
    assert t(tau=last) == 0  # the next finite torque equal to the last finite one passes
    assert t.mon.counts == {**dict.fromkeys(KINDS, 0), "nonfinite": 2}
    assert t.mon.torque_rate_max_nm_s == pytest.approx(0.9 / DT, rel=1e-9)
    # and the reference is the last finite torque, not the one before it
    assert t(tau=_step(last, j, 1.0 + EPS)) == BITS["torque_rate"]


@pytest.mark.parametrize("kind", list(NONFINITE))
def test_nonfinite_after_finite_then_step_measured_against_last_finite(kind):
    t = Tick()
    a = _step(TAU0, 1, 0.8)
    assert t(tau=a) == 0
    assert t(tau=NONFINITE[kind](a, 1)) == BITS["nonfinite"]
    assert t(tau=_step(a, 1, 0.8)) == 0  # 0.8 from the last finite, 1.6 from the reset torque


@pytest.mark.parametrize("kind", list(NONFINITE))
def test_nonfinite_ddq_command_is_nonfinite_and_keeps_the_jerk_reference(kind):
    ddq0 = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
    t = Tick(ddq_start=ddq0)
    assert t(ddq=NONFINITE[kind](ddq0, 5)) == BITS["nonfinite"]
    assert t(ddq=ddq0) == 0
    assert t.mon.counts["nonfinite"] == 1 and t.mon.counts["jerk"] == 0


def test_the_other_torque_joints_are_still_held_to_their_limit_on_a_nonfinite_tick():
    t = Tick(tau_start=_step(TAU0, 4, 12.0 - TAU0[4]))  # joint 5 at its 12 N m limit
    bad = NONFINITE["qnan"](_step(TAU0, 4, 12.0 - TAU0[4] + EPS), 0)
    assert t(tau=bad) == BITS["nonfinite"] | BITS["torque"]


# ---------------------------------------------------------------- effort limit (recommended)


@pytest.mark.parametrize("j", range(7))
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_torque_at_limit_passes_just_beyond_flagged(j, sign):
    at = TAU0.copy()
    at[j] = sign * LIM["tau_max_nm"][j]
    t = Tick(tau_start=at)  # start there so the rate condition stays out of it
    assert t(tau=at) == 0
    assert t(tau=_step(at, j, -sign * EPS)) == 0
    assert t(tau=at) == 0
    assert _counts_zero(t.mon)
    assert t(tau=_step(at, j, sign * EPS)) == BITS["torque"]
    assert t.mon.counts["torque"] == 1 and t.mon.violations == 1


# ---------------------------------------------------------------- joint-space motion conditions


@pytest.mark.parametrize("j", range(7))
def test_position_at_limits_passes_just_outside_flagged(j):
    t = Tick()
    for n_side, (name, outward) in enumerate((("q_max_rad", 1.0), ("q_min_rad", -1.0))):
        at = Q0.copy()
        at[j] = LIM[name][j]
        assert t(q=at) == 0
        assert t(q=_step(at, j, -outward * EPS)) == 0
        # the tolerance is 1e-9 relative to the limit: half of it passes, twice it is flagged
        assert t(q=_step(at, j, outward * 0.5e-9 * abs(LIM[name][j]))) == 0
        assert t.mon.counts == {**dict.fromkeys(KINDS, 0), "position": 2 * n_side}
        assert t(q=_step(at, j, outward * EPS)) == BITS["position"]
        assert t(q=_step(at, j, outward * 2e-9 * abs(LIM[name][j]))) == BITS["position"]
    assert t.mon.counts["position"] == 4 and t.mon.violations == 4


@pytest.mark.parametrize("j", range(7))
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_velocity_at_limit_passes_just_beyond_flagged(j, sign):
    t = Tick()
    dq = ZERO7.copy()
    dq[j] = sign * LIM["v_max_rad_s"][j]
    assert t(dq=dq) == 0
    assert t(dq=_step(dq, j, -sign * EPS)) == 0
    assert _counts_zero(t.mon)
    assert t(dq=_step(dq, j, sign * EPS)) == BITS["velocity"]


@pytest.mark.parametrize("j", range(7))
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_accel_at_limit_passes_just_beyond_flagged(j, sign):
    at = ZERO7.copy()
    at[j] = sign * LIM["a_max_rad_s2"][j]
    t = Tick(ddq_start=at)  # start there so the jerk condition stays out of it
    assert t(ddq=at) == 0
    assert t(ddq=_step(at, j, -sign * EPS)) == 0
    assert t(ddq=at) == 0
    assert _counts_zero(t.mon)
    assert t(ddq=_step(at, j, sign * EPS)) == BITS["accel"]


@pytest.mark.parametrize("j", range(7))
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_jerk_just_inside_passes_just_outside_flagged(j, sign):
    step = LIM["j_max_rad_s3"][j] * DT  # largest ddq change in one tick
    t = Tick(ddq_start=np.full(7, 0.37))
    ddq = _step(t.ddq, j, sign * (step - EPS))
    assert t(ddq=ddq) == 0
    ddq = _step(ddq, j, -sign * step)  # exactly at the limit, back
    assert t(ddq=ddq) == 0
    assert _counts_zero(t.mon)
    assert t(ddq=_step(ddq, j, sign * (step + EPS))) == BITS["jerk"]
    assert t.mon.counts["jerk"] == 1


def test_jerk_limit_is_per_joint():
    """4 rad/s^2 in one tick is 4000 rad/s^3: beyond joint 2's 3750, within joint 7's 10000."""
    assert t_jerk(1, 4.0) == BITS["jerk"]
    assert t_jerk(6, 4.0) == 0
    assert t_jerk(1, 3.75 - EPS) == 0
    assert t_jerk(6, 10.0 - EPS) == 0
    assert t_jerk(6, 10.0 + EPS) == BITS["jerk"]


def t_jerk(j: int, delta: float) -> int:
    t = Tick()
    return t(ddq=_step(ZERO7, j, delta))


@pytest.mark.parametrize("direction", [(1, 0, 0), (0, -1, 0), (0, 0, 1), (1, 1, 1), (-0.3, 0.8, 0.52)])
def test_tcp_speed_at_limit_passes_just_beyond_flagged(direction):
    u = np.array(direction, dtype=float)
    u /= np.linalg.norm(u)
    t = Tick()
    assert t(v=1.7 * u) == 0
    assert t(v=(1.7 - EPS) * u) == 0
    assert _counts_zero(t.mon)
    assert t(v=(1.7 + EPS) * u) == BITS["tcp_speed"]


@pytest.mark.parametrize("arg", ["q", "dq", "v"])
@pytest.mark.parametrize("kind", list(NONFINITE))
def test_nonfinite_measured_state_is_flagged_under_its_own_kind(arg, kind):
    expected = {"q": BITS["position"], "dq": BITS["velocity"], "v": BITS["tcp_speed"]}[arg]
    base = {"q": Q0, "dq": ZERO7, "v": ZERO3}[arg]
    t = Tick()
    assert t(**{arg: NONFINITE[kind](base, 1)}) == expected


# ---------------------------------------------------------------- bookkeeping


def test_counts_ticks_violations_add_up():
    t = Tick()
    tau1 = _step(_step(TAU0, 0, 1.5), 6, -2.0)
    masks = [
        t(),
        t(tau=tau1),  # two joints break the rate: one tick
        t(tau=tau1),
        t(tau=tau1, q=_step(Q0, 3, 4.0), dq=np.full(7, 3.0)),
        t(tau=NONFINITE["snan"](tau1, 2)),
        t(tau=tau1, ddq=np.full(7, 100.0)),  # accel and jerk on every joint: counted once each
        t(tau=tau1, ddq=np.full(7, 100.0)),  # accel only (no change)
        t(tau=tau1, v=np.array([2.0, 0.0, 0.0])),  # back to ddq 0: jerk
        t(tau=tau1),
    ]
    assert [describe(m) for m in masks] == [
        [], ["torque_rate"], [], ["position", "velocity"], ["nonfinite"],
        ["accel", "jerk"], ["accel"], ["jerk", "tcp_speed"], [],
    ]
    assert t.mon.counts == {
        "nonfinite": 1, "torque_rate": 1, "torque": 0, "position": 1, "velocity": 1, "accel": 2, "jerk": 2,
        "tcp_speed": 1,
    }
    assert t.mon.ticks == len(masks)
    assert t.mon.violations == sum(m != 0 for m in masks) == 6
    assert sum(t.mon.counts.values()) == sum(bin(m).count("1") for m in masks)
    assert t.mon.last_mask == masks[-1] == 0
    assert t.mon.torque_rate_max_nm_s == pytest.approx(2.0 / DT, rel=1e-9)


def test_describe():
    assert describe(0) == []
    assert describe(BITS["jerk"] | BITS["torque"]) == ["torque", "jerk"]
    assert describe((1 << len(KINDS)) - 1) == list(KINDS)
    assert SafetyMonitor.describe(BITS["nonfinite"]) == ["nonfinite"]
    assert [BITS[k] for k in KINDS] == [1 << i for i in range(len(KINDS))]
    with pytest.raises(ValueError):
        describe(1 << len(KINDS))
    with pytest.raises(ValueError):
        describe(-1)


def test_inputs_of_other_types_and_layouts_give_the_same_mask():
    rng = np.random.default_rng(1)
    tau = TAU0 + rng.uniform(-2, 2, 7)
    q, dq, ddq, v = Q0 + 0.1, rng.uniform(-3, 3, 7), rng.uniform(-20, 20, 7), np.array([1.0, 1.2, 0.4])
    ref = Tick()
    expected = ref(tau=tau, q=q, dq=dq, ddq=ddq, v=v)
    assert expected != 0
    strided = np.zeros((7, 2))
    strided[:, 0] = tau
    for variant in (
        dict(tau=list(tau), q=tuple(q), dq=dq, ddq=list(ddq), v=list(v)),
        dict(tau=strided[:, 0], q=q, dq=dq[::-1][::-1], ddq=ddq, v=v),
        dict(tau=tau.astype(np.longdouble), q=q, dq=dq.astype(">f8"), ddq=ddq, v=v),
    ):
        assert Tick()(**variant) == expected
    # float32 / int inputs: the same mask as their float64 values
    f32 = [x.astype(np.float32) for x in (tau, q, dq, ddq, v)]
    assert Tick()(*f32) == Tick()(*[x.astype(np.float64) for x in f32]) != 0
    ints = [np.round(x).astype(np.int32) for x in (tau, q, dq, ddq, v)]
    assert Tick()(*ints) == Tick()(*[x.astype(np.float64) for x in ints])
    t = Tick()
    names = {"tau": "tau_nm", "q": "q_rad", "v": "tcp_vel_m_s", "dq": "dq_rad_s"}
    for arg, bad in (("tau", np.zeros(6)), ("q", np.zeros((7, 1))), ("v", np.zeros(7)), ("dq", [0.0] * 8)):
        with pytest.raises(ValueError, match=names[arg]):
            t(**{arg: bad})
    assert t.mon.ticks == 0  # a rejected call changes nothing


# ---------------------------------------------------------------- against a plain reference


def _reference(stream, tau_start, ddq_start, tol=1e-9):
    """The spec in plain numpy, one tick at a time: masks, per-kind counts, largest torque rate."""
    tau_last, ddq_last, rate_max = np.array(tau_start, float), np.array(ddq_start, float), 0.0
    masks = []
    for tau, q, dq, ddq, v in stream:
        bad = set()
        fin_t, fin_a = np.isfinite(tau), np.isfinite(ddq)
        if not (fin_t.all() and fin_a.all()):
            bad.add("nonfinite")
        if np.any(np.abs(tau[fin_t]) > LIM["tau_max_nm"][fin_t] * (1 + tol)):
            bad.add("torque")
        if np.any(np.abs(ddq[fin_a]) > LIM["a_max_rad_s2"][fin_a] * (1 + tol)):
            bad.add("accel")
        if fin_t.all():
            r = np.abs(tau - tau_last) / DT
            rate_max = max(rate_max, r.max())
            if np.any(r > 1000.0 * (1 + tol)):
                bad.add("torque_rate")
            tau_last = tau.copy()
        if fin_a.all():
            if np.any(np.abs(ddq - ddq_last) / DT > LIM["j_max_rad_s3"] * (1 + tol)):
                bad.add("jerk")
            ddq_last = ddq.copy()
        lo = LIM["q_min_rad"] - tol * np.abs(LIM["q_min_rad"])
        hi = LIM["q_max_rad"] + tol * np.abs(LIM["q_max_rad"])
        if not np.all((q >= lo) & (q <= hi)):
            bad.add("position")
        if not np.all(np.abs(dq) <= LIM["v_max_rad_s"] * (1 + tol)):
            bad.add("velocity")
        vx, vy, vz = (float(x) for x in v)
        if not math.sqrt(vx * vx + vy * vy + vz * vz) <= 1.7 * (1 + tol):
            bad.add("tcp_speed")
        masks.append(sum(BITS[k] for k in bad))
    return masks, rate_max


def test_kernel_matches_a_plain_reference_on_random_sequences_near_the_limits():
    rng = np.random.default_rng(7)
    n = 3000
    mid, half = (LIM["q_max_rad"] + LIM["q_min_rad"]) / 2, (LIM["q_max_rad"] - LIM["q_min_rad"]) / 2
    tau = TAU0 + np.cumsum(rng.uniform(-1.02, 1.02, (n, 7)), axis=0)
    tau = np.clip(tau, -LIM["tau_max_nm"] * 1.01, LIM["tau_max_nm"] * 1.01)
    q = mid + half * rng.uniform(-1.003, 1.003, (n, 7))
    dq = LIM["v_max_rad_s"] * rng.uniform(-1.003, 1.003, (n, 7))
    ddq = np.clip(np.cumsum(rng.uniform(-1, 1, (n, 7)) * LIM["j_max_rad_s3"] * DT * 1.01, axis=0),
                  -LIM["a_max_rad_s2"] * 1.005, LIM["a_max_rad_s2"] * 1.005)
    v = rng.normal(size=(n, 3))
    v *= (1.7 * rng.uniform(0.99, 1.01, n) / np.linalg.norm(v, axis=1))[:, None]
    for k in rng.choice(n, 40, replace=False):  # sprinkle non-finite values
        arr = [tau, ddq, q, dq, v][k % 5]
        arr[k, k % arr.shape[1]] = [np.nan, np.inf, -np.inf, _snan()][k % 4]
    stream = list(zip(tau, q, dq, ddq, v))
    mon = SafetyMonitor()
    mon.reset(TAU0)
    got = [mon.check(*s) for s in stream]
    want, rate_max = _reference(stream, TAU0, ZERO7)
    assert got == want
    assert mon.torque_rate_max_nm_s == pytest.approx(rate_max, rel=1e-12)
    assert mon.ticks == n and mon.violations == sum(m != 0 for m in want)
    assert mon.counts == {k: sum(bool(m & BITS[k]) for m in want) for k in KINDS}
    assert all(0 < c < n for c in mon.counts.values())  # every kind both seen and not seen


# ---------------------------------------------------------------- limits


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(dt_s=0.0), "dt_s"),
        (dict(dt_s=-0.001), "dt_s"),
        (dict(dt_s=float("nan")), "dt_s"),
        (dict(dt_s=float("inf")), "dt_s"),
        (dict(dtau_max_nm_s=0.0), "dtau_max_nm_s"),
        (dict(dtau_max_nm_s=float("inf")), "dtau_max_nm_s"),
        (dict(tcp_speed_max_m_s=-1.7), "tcp_speed_max_m_s"),
        (dict(tcp_speed_max_m_s=float("nan")), "tcp_speed_max_m_s"),
        (dict(joint=JointLimits(tau_max_nm=(87.0,) * 4 + (12.0, 12.0, 0.0))), r"tau_max_nm\[6\]"),
        (dict(joint=JointLimits(v_max_rad_s=(2.175, float("nan")) + (2.175,) * 5)), r"v_max_rad_s\[1\]"),
        (dict(joint=JointLimits(a_max_rad_s2=(15.0,) * 7 + (1.0,))), "a_max_rad_s2"),
        (dict(joint=JointLimits(j_max_rad_s3=(-1.0,) * 7)), r"j_max_rad_s3\[0\]"),
        (dict(joint=JointLimits(q_max_rad=(float("inf"),) * 7)), r"q_max_rad\[0\]"),
        (dict(joint=JointLimits(q_min_rad=(3.0,) + JointLimits().q_min_rad[1:])), r"q_min_rad\[0\]"),
        (dict(joint="panda"), "joint"),
    ],
)
def test_command_limits_reject_bad_values_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        CommandLimits(**kwargs)


def test_command_limits_defaults_are_the_panda():
    c = CommandLimits()
    assert (c.dt_s, c.dtau_max_nm_s, c.tcp_speed_max_m_s) == (0.001, 1000.0, 1.7)
    assert c.joint == JointLimits()
    with pytest.raises(AttributeError):
        c.dt_s = 0.002  # frozen


def test_other_period_scales_the_rate_conditions():
    """At 500 Hz the same 1000 N m/s allows 2 N m per tick, 3750 rad/s^3 on joint 2 allows 7.5 rad/s^2."""
    ddq0 = _step(ZERO7, 1, -3.0)
    for delta, expected in ((-EPS, 0), (EPS, BITS["torque_rate"] | BITS["jerk"])):
        t = Tick(limits=CommandLimits(dt_s=0.002), ddq_start=ddq0)
        assert t(tau=_step(TAU0, 0, 2.0 + delta), ddq=_step(ddq0, 1, 7.5 + delta)) == expected


def test_safety_imports_only_numpy_numba_the_robot_description_and_the_layout_helper():
    """controllers/ may drive a real arm: no mujoco, nothing of mmact_ctrl/scenarios/policy."""
    src = Path(__file__).resolve().parents[1] / "controllers" / "safety.py"
    names = set()
    for node in ast.walk(ast.parse(src.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            names.add(node.module)
    third_party = {n for n in names if n.split(".")[0] not in sys.stdlib_module_names and n != "__future__"}
    assert third_party <= {"numpy", "numba", "controllers.robot_description", "controllers.layout"}, third_party
