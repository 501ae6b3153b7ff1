"""The MPC previews only the descent the descent governor allows (``DescentGovernor.lowest_z_m``, ``PlanTracker``'s
``preview_low``): the governor's prediction against its own descent, the preview held above it, and in the loop the
open hand centred over the cube on its way down (it was 14 mm off sideways on a static cube, the plan trading the
other axes for a height the governor would not let it reach)."""

from __future__ import annotations

import numpy as np
import pytest

from mmact_ctrl.control.descent import DescentGovernor
from mmact_ctrl.metrics import episode_metrics
from scenarios.world.tasks.pick import DESCENT_BAND_M
from pick_episode import run_pick_episode

DT = 0.001
FLOOR_M = 0.05


def _governor() -> DescentGovernor:
    return DescentGovernor(DESCENT_BAND_M, 0.05, FLOOR_M, DT)


def test_before_its_first_tick_the_governor_bounds_nothing():
    assert _governor().lowest_z_m(np.array([0.04, 0.08])) is None


@pytest.mark.parametrize("z0_m", [0.20, DESCENT_BAND_M[1] + 0.004, DESCENT_BAND_M[0] + 0.002])
def test_the_predicted_lowest_heights_are_the_governors_own_descent(z0_m):
    gov = _governor()
    gov(np.array([0.5, 0.0, z0_m]), np.zeros(3), np.zeros(3))  # the reference is at z0 now
    delays = 0.04 * np.arange(1, 11)  # the MPC's knots
    low = gov.lowest_z_m(delays)
    # the governor's own descent of a reference that falls far below it, tick by tick, from the same height
    ticks = np.array([gov(np.array([0.5, 0.0, -1.0]), np.zeros(3), np.zeros(3))[0][2] for _ in range(400)])
    own = ticks[np.rint(delays / DT).astype(int) - 1]
    assert np.all(np.diff(low) <= 0.0) and np.all(low >= min(FLOOR_M, z0_m) - 1e-12)
    assert np.max(np.abs(low - own)) < 1.5e-3  # the 5 ms integration against the 1 ms ticks
    assert own[-1] < z0_m - 0.005  # it did come down


@pytest.mark.parametrize("target,speed,seed,max_off_mm", [("static", "0", 6001, 4.0), ("linear", "0.2", 6001, 8.0)])
def test_the_open_hand_comes_down_centred_over_the_cube(target, speed, seed, max_off_mm):
    """The TCP's sideways offset from the instructed cube while the open fingers come down past its top (TCP 10-30 mm
    above its centre, before the grasp). Before the preview was bounded: 14 mm (static) and 26 mm (0.2 m/s)."""
    log, _, _ = run_pick_episode(target, speed, seed, "6")
    assert log.task["success"]
    cube = log.objects_pos_m[:, log.target_index]
    above = log.ee_pos_m[:, 2] - cube[:, 2]
    down = (above > 0.01) & (above < 0.03) & (log.t_s < log.task["time_to_grasp_s"] - 0.2)
    assert down.sum() > 30
    off_mm = 1e3 * np.linalg.norm((log.ee_pos_m - cube)[down, :2], axis=1)
    assert np.median(off_mm) < max_off_mm
    m = episode_metrics(log)
    assert m["contact_force_violations"] == 0 and m["limit_violations"] == 0, m
