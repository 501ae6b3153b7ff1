"""The simulator's floor for pick's landings: how fast an open finger may come down onto a cube and stay under the limit.

What is left of pick's contact forces over 30 N is the landing itself: the force peaks within a tick or two of the
first touch, before any layer can react. This measures that peak against the landing speed, with the whole stack in
the loop and nothing else moving. The cube is alone and static on the carrier; a scripted chunk brings the open hand
over it with one finger's pad centred over the cube's top, holds, then comes straight down at ``--speeds`` (m/s) to
``PRESS_M`` under the top and holds there. Per speed: the hand's measured speed when the fingertip reaches the cube's
top, the peak force on the robot within ``SPIKE_WINDOW_S`` of the first touch (over ``TOUCH_N``), the ticks over the
limit in the whole episode, and the peak's own. The modes are the ones that do not read the object (in those that
do, the capture gate keeps an open hand off a cube that is not between its fingers, so nothing lands), without the
band's landing speed that pick's stack sets from this measurement (``StackConfig.landing_speed_m_s``):

    python -m scenarios.landing_floor                              # open_loop, stiff and --compliance, a table
    python -m scenarios.landing_floor --speeds 0.05 0.1 --json out/landing.json
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import run_episode
from scenarios.world.panda_scene import SceneConfig
from scenarios.world.tasks.grip import FINGER_BODIES
from scenarios.world.tasks.pick import FINGERTIP_BELOW_TCP_M, PickWorld, pick_target_spec
from scenarios.world.tasks.pick_scene import CUBE_HALF_M, CUBE_REST_Z_M
from scenarios.world.tasks.registry import task_by_name, task_stack_settings

DEFAULT_SPEEDS_M_S = (0.05, 0.1, 0.15, 0.17, 0.2, 0.25, 0.3)
#: the open fingertip hovers this far above the cube's top before the descent, m
HOVER_M = 0.04
#: the reference goes this far under the cube's top, m (a finger that lands presses on)
PRESS_M = 0.005
#: the move to the hover point, the hold there, s
MOVE_S, HOLD_S = 1.5, 0.5
#: a touch: the force on the robot over this, N; the landing's spike: the peak within this after the first touch, s
TOUCH_N, SPIKE_WINDOW_S = 1.0, 0.02
#: how long the episode runs on after the reference has reached its bottom, s
AFTER_S = 0.5
GRIPPER_OPEN_M = 0.08


@dataclass(frozen=True)
class Landing:
    """One landing: the mode, the commanded descent speed (m/s), the hand's measured speed as the fingertip reached
    the cube's top (m/s), the peak force within ``SPIKE_WINDOW_S`` of the first touch (N) and how long after the
    touch it came (ms), the episode's peak (N), its ticks over the limit, the limit (N)."""

    mode: str
    compliance: bool
    speed_cmd_m_s: float
    landing_speed_m_s: float
    spike_n: float
    spike_after_ms: float
    peak_n: float
    ticks_over_limit: int
    limit_n: float


class _ForceRecordingPickWorld(PickWorld):
    """The pick world, keeping the measured contact force's magnitude at each step it is read (N)."""

    def reset(self, seed: int, *args, **kwargs):
        self.forces_n: dict[float, float] = {}
        return super().reset(seed, *args, **kwargs)

    def measured_wrench(self) -> np.ndarray | None:
        w = super().measured_wrench()
        if w is not None:
            self.forces_n[round(float(self.data.time), 6)] = float(np.linalg.norm(w[:3]))
        return w


def _world() -> _ForceRecordingPickWorld:
    task = task_by_name("pick")
    scene = SceneConfig(**{**dict(n_objects=1, image_size_px=64, camera_names=("front",), task="pick"),
                           **task.scene_overrides})
    return _ForceRecordingPickWorld(scene, pick_target_spec("static", 0.0), noise_m=0.0, dropout=0.0)


class LandingSource:
    """A chunk source on an absolute-time path: to the hover point over the cube with one finger's pad over the cube's
    top, a hold, then straight down at ``speed_m_s`` to ``PRESS_M`` under the top (see the module)."""

    needs_image = False
    name = "landing-probe"

    def __init__(self, world: PickWorld, speed_m_s: float, horizon: int = 100, dt_s: float = 0.02) -> None:
        m, d = world.model, world.data
        tcp = d.site_xpos[world._tcp].copy()
        pad = d.geom_xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{FINGER_BODIES[1][0]}_pad")].copy()
        cube = world.target_pos_m()
        self.start_m = tcp
        over_z = CUBE_REST_Z_M + CUBE_HALF_M + FINGERTIP_BELOW_TCP_M  # the TCP's height as the fingertip meets the top
        self.hover_m = np.array([cube[0] - (pad[0] - tcp[0]), cube[1] - (pad[1] - tcp[1]), over_z + HOVER_M])
        self.bottom_z_m = over_z - PRESS_M
        self.speed_m_s, self.horizon, self.dt_s = float(speed_m_s), int(horizon), float(dt_s)

    @property
    def chunk_dt_s(self) -> float:
        return self.dt_s

    def position_m(self, t_s: float) -> np.ndarray:
        """The path's position at time ``t_s`` (m)."""
        if t_s < MOVE_S:
            s = t_s / MOVE_S
            s = s**3 * (10.0 - 15.0 * s + 6.0 * s**2)
            return self.start_m + s * (self.hover_m - self.start_m)
        z = self.hover_m[2] - self.speed_m_s * max(0.0, t_s - MOVE_S - HOLD_S)
        return np.array([self.hover_m[0], self.hover_m[1], max(z, self.bottom_z_m)])

    def plan(self, observation: Observation) -> ActionChunk:
        times = observation.t0_s + self.dt_s * np.arange(1, self.horizon + 1)
        waypoints = np.zeros((self.horizon, 7))
        waypoints[:, :3] = [self.position_m(float(t)) for t in times]
        waypoints[:, 6] = GRIPPER_OPEN_M
        return ActionChunk(waypoints=waypoints, dt_s=self.dt_s, t0_s=observation.t0_s)


def land(speed_m_s: float, mode: str = "open_loop", compliance: bool = False, seed: int = 0,
         landing_speed: bool = False) -> Landing:
    """One landing at ``speed_m_s`` (see the module): the simulator's own, the band's landing speed off
    (``StackConfig.landing_speed_m_s``, which is set from this measurement); ``landing_speed``: with it, as pick's
    stack runs."""
    world = _world()
    try:
        world.reset(seed)  # the source reads the reset scene's geometry; the episode resets it again
        source = LandingSource(world, speed_m_s)
        duration_s = MOVE_S + HOLD_S + (HOVER_M + PRESS_M) / float(speed_m_s) + AFTER_S
        settings = task_stack_settings("pick", compliance=compliance)
        if not landing_speed:
            settings["landing_speed_m_s"] = None
        cfg = StackConfig(mode=mode, duration_s=duration_s, **settings)
        log = run_episode(world, source, HybridController(cfg), seed=seed)
        forces = world.forces_n
    finally:
        world.close()
    t_f = np.array(sorted(forces))
    f = np.array([forces[t] for t in t_f])
    touch = np.flatnonzero(f > TOUCH_N)
    limit = float(cfg.contact_force_limit_n)
    if touch.size == 0:
        return Landing(mode, compliance, speed_m_s, float("nan"), 0.0, float("nan"), float(f.max(initial=0.0)), 0,
                       limit)
    t_touch = float(t_f[touch[0]])
    window = (t_f >= t_touch) & (t_f <= t_touch + SPIKE_WINDOW_S)
    i_spike = int(np.argmax(np.where(window, f, -1.0)))
    over_z = CUBE_REST_Z_M + CUBE_HALF_M + FINGERTIP_BELOW_TCP_M
    z = log.ee_pos_m[:, 2]
    k = int(np.argmax(z <= over_z)) if np.any(z <= over_z) else int(np.searchsorted(log.t_s, t_touch))
    k = max(1, min(k, len(z) - 1))
    v_land = float(-(z[k] - z[k - 1]) / (log.t_s[k] - log.t_s[k - 1]))
    return Landing(mode, compliance, speed_m_s, v_land, float(f[i_spike]), 1000.0 * (float(t_f[i_spike]) - t_touch),
                   float(f.max()), int(np.count_nonzero(f > limit)), limit)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0.0 < value <= 1.0:
        raise argparse.ArgumentTypeError(f"a landing speed is in (0, 1] m/s, got {text}")
    return value


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m scenarios.landing_floor", description=__doc__.split("\n\n")[0])
    p.add_argument("--speeds", type=_positive, nargs="+", default=list(DEFAULT_SPEEDS_M_S),
                   help="descent speeds, m/s (default: %(default)s)")
    p.add_argument("--no-compliance", action="store_true", help="stiff tracking only (default: stiff, then "
                   "--compliance)")
    p.add_argument("--json", default=None, help="also write the rows to this file")
    args = p.parse_args(argv)
    rows = []
    print(f"{'mode':>22} {'cmd [m/s]':>9} {'landing [m/s]':>13} {'spike [N]':>9} {'after [ms]':>10} "
          f"{'peak [N]':>8} {'ticks > limit':>13}", flush=True)
    for compliance in ((False,) if args.no_compliance else (False, True)):
        for v in args.speeds:
            r = land(v, compliance=compliance)
            rows.append(r)
            name = r.mode + (" --compliance" if r.compliance else "")
            print(f"{name:>22} {r.speed_cmd_m_s:9.2f} {r.landing_speed_m_s:13.3f} {r.spike_n:9.1f} "
                  f"{r.spike_after_ms:10.0f} {r.peak_n:8.1f} {r.ticks_over_limit:13d}", flush=True)
    for compliance in sorted({r.compliance for r in rows}):
        mine = [r for r in rows if r.compliance == compliance and np.isfinite(r.landing_speed_m_s)]
        under = [r.landing_speed_m_s for r in mine if r.spike_n <= r.limit_n]
        over = [r.landing_speed_m_s for r in mine if r.spike_n > r.limit_n]
        name = "open_loop" + (" --compliance" if compliance else "")
        print(f"{name}: fastest landing under the limit {max(under, default=float('nan')):.3f} m/s; "
              f"slowest over it {min(over, default=float('nan')):.3f} m/s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump([asdict(r) for r in rows], fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
