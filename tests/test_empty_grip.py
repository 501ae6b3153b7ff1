"""The empty-grip gate (``mmact_ctrl.control.empty_grip``): on hand-built states, and in the loop on the pick episode
where it was measured to be needed."""

from __future__ import annotations

import numpy as np

from mmact_ctrl.control.empty_grip import RISE_M_S, EmptyGripGate
from mmact_ctrl.metrics import episode_metrics
from pick_episode import run_pick_episode

DT = 0.001
SAFE_Z = 0.06


def _ref(z: float):
    return np.array([0.4, 0.1, z]), np.array([0.3, 0.0, -0.05]), np.zeros(3)


def test_fingers_closed_past_the_object_lift_the_hand_and_keep_its_course():
    gate = EmptyGripGate(0.03, SAFE_Z, DT)
    pos, vel, acc = _ref(0.03)
    assert gate(pos, vel, acc, 0.031, 0.05, 100)[0] is pos  # closing, still wider than an object: nothing yet
    assert gate(pos, vel, acc, 0.031, 0.01, 0)[0] is pos  # commanded open: a narrow opening is no closing
    assert gate(pos, vel, acc, 0.031, None, 100)[0] is pos  # not measured
    out = [gate(*_ref(0.03), 0.031, 0.01, 100) for _ in range(50)]
    assert gate.active and gate.missed == 1 and gate.held_ticks == 50
    z = np.array([p[0][2] for p in out])
    assert np.allclose(np.diff(z), RISE_M_S * DT) and z[0] > 0.031
    assert all(p[1][2] >= RISE_M_S and p[2][2] >= 0.0 for p in out)
    assert all(np.allclose(p[0][:2], [0.4, 0.1]) and p[1][0] == 0.3 for p in out)  # the chunk's course goes on
    # the gate holds on while the TCP is below the band's top, even when the fingers reopen, and lets go up there
    assert gate(*_ref(0.03), 0.05, 0.08, 0)[0][2] > 0.03
    pos, vel, acc = _ref(0.03)
    assert gate(pos, vel, acc, SAFE_Z + 0.001, 0.01, 100)[0] is pos and not gate.active
    gate.reset()
    assert not gate.active and gate.missed == 0


def test_a_blind_hand_that_closed_on_nothing_is_not_struck_by_the_cube_it_missed():
    """Pick at 0.4 m/s, open loop, tuning seed 6015: the fingers closed 3 cm ahead of the cube; the closed hand slowed
    at its chunk's end, low beside the cube, and the carried cube struck it (30.8 N). The gate lifts it at once."""
    log, ctl, _ = run_pick_episode("linear", "0.4", 6015, "4.5", mode="open_loop")
    assert ctl.empty_grip.missed > 0
    m = episode_metrics(log)
    assert m["contact_force_violations"] == 0 and m["limit_violations"] == 0, m
