"""The simulator's own floor for insert: the smallest clearance at which a perfectly aligned, slowly pushed peg seats.

MuJoCo's contacts are soft (a constraint acts from its margin, and bodies interpenetrate by a fraction of a mm under
load), so below some clearance a hole is no longer a hole the way a real one is. This measures it without the robot:
the peg, alone, upright, its axis on the hole's axis, starts ``START_ABOVE_M`` over the mouth and is pushed down by a
spring (``PUSH_STIFFNESS_N_M``, capped at ``PUSH_FORCE_MAX_N``) whose anchor descends at ``PUSH_SPEED_M_S``; the peg is
otherwise free (it may tilt and slide). It seats when its bottom is ``SEAT_M`` (20 mm) below the mouth within
``TIME_LIMIT_S``. The arm stays at home, gravity-compensated, far from the fixture.

    python -m scenarios.insert_floor                         # the default clearances, a table
    python -m scenarios.insert_floor --clearances-mm 1 0.1 0.01 --json out/floor.json
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from scenarios.world.factory import make_world
from scenarios.world.tasks.insert import SEAT_M

PUSH_SPEED_M_S = 0.01
PUSH_STIFFNESS_N_M = 1000.0
PUSH_FORCE_MAX_N = 10.0
START_ABOVE_M = 0.005
TIME_LIMIT_S = 4.0
DEFAULT_CLEARANCES_MM = (1.0, 0.5, 0.25, 0.1, 0.05, 0.02, 0.01)


@dataclass(frozen=True)
class AlignedPush:
    """One aligned push: the clearance (mm per side), whether it seated, when (s), the depth reached (m), the largest
    tilt of the peg (deg) and the largest push (N)."""

    clearance_mm: float
    seated: bool
    time_to_seat_s: float | None
    depth_m: float
    max_tilt_deg: float
    max_push_n: float


def aligned_push(clearance_mm: float, offset_mm: float = 0.0, tilt_deg: float = 0.0) -> AlignedPush:
    """Push the peg, aligned, into a hole of ``clearance_mm`` per side (see the module); ``offset_mm`` moves its axis
    off the hole's along x and ``tilt_deg`` tilts it about y (both 0: perfectly aligned)."""
    world = make_world(task="insert", target="static", speed_m_s=0.0, noise_m=0.0, dropout=0.0,
                       clearance_mm=clearance_mm)
    world.reset(0)
    m, d = world.model, world.data
    d.ctrl[world._grip_act] = 0.08  # the fingers open, away from the peg
    mouth = world.target_pos_m()
    peg_q, peg_body = world._peg_q, m.jnt_bodyid[m.body_jntadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "peg")]]
    half_len = float(m.geom_size[world._peg_geom][2])
    z0 = mouth[2] + START_ABOVE_M + half_len  # the peg's centre
    d.qpos[peg_q:peg_q + 3] = [mouth[0] + offset_mm / 1000.0, mouth[1], z0]
    half = np.radians(tilt_deg) / 2.0
    d.qpos[peg_q + 3:peg_q + 7] = [np.cos(half), 0.0, np.sin(half), 0.0]
    d.qvel[:] = 0.0
    mujoco.mj_forward(m, d)
    arm_dof = world._arm_dof
    seat_s, depth, tilt, push_max = None, -np.inf, 0.0, 0.0
    steps = int(round(TIME_LIMIT_S / m.opt.timestep))
    for k in range(steps):
        t = k * m.opt.timestep
        d.qfrc_applied[arm_dof] = d.qfrc_bias[arm_dof]
        anchor = z0 - PUSH_SPEED_M_S * t
        push = float(np.clip(-PUSH_STIFFNESS_N_M * (d.qpos[peg_q + 2] - anchor), -PUSH_FORCE_MAX_N, PUSH_FORCE_MAX_N))
        d.xfrc_applied[peg_body, 2] = push
        push_max = max(push_max, -push)
        mujoco.mj_step(m, d)
        bottom = world.peg_bottom_m()
        depth = max(depth, float(mouth[2] - bottom[2]))
        z_axis = d.xmat[peg_body].reshape(3, 3)[:, 2]
        tilt = max(tilt, float(np.degrees(np.arccos(np.clip(z_axis[2], -1.0, 1.0)))))
        if seat_s is None and mouth[2] - bottom[2] >= SEAT_M:
            seat_s = float(d.time)
            break
    return AlignedPush(clearance_mm=float(clearance_mm), seated=seat_s is not None, time_to_seat_s=seat_s,
                       depth_m=float(depth), max_tilt_deg=tilt, max_push_n=push_max)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m scenarios.insert_floor", description=__doc__.split("\n\n")[0])
    p.add_argument("--clearances-mm", type=float, nargs="+", default=list(DEFAULT_CLEARANCES_MM), metavar="MM",
                   help="clearances per side to try, mm (default: %(default)s)")
    p.add_argument("--offset-mm", type=float, default=0.0, help="the peg's axis this far off the hole's, mm (default 0)")
    p.add_argument("--tilt-deg", type=float, default=0.0, help="the peg tilted this much, deg (default 0)")
    p.add_argument("--json", metavar="PATH", help="write the results as JSON")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    bad = [c for c in args.clearances_mm if not (np.isfinite(c) and 0.0 < c <= 5.0)]
    if bad:
        print(f"error: --clearances-mm must be in (0, 5] mm, got {bad[0]!r}",
              file=sys.stderr)
        return 2
    for name, v, hi in (("--offset-mm", args.offset_mm, 4.0), ("--tilt-deg", args.tilt_deg, 10.0)):
        if not (np.isfinite(v) and abs(v) <= hi):
            print(f"error: {name} must be within +-{hi:g}, got {v!r}", file=sys.stderr)
            return 2
    rows = [aligned_push(c, args.offset_mm, args.tilt_deg) for c in args.clearances_mm]
    print(f"{'clearance [mm]':>15} {'seated':>7} {'time [s]':>9} {'depth [mm]':>11} {'tilt [deg]':>11} {'push [N]':>9}")
    for r in rows:
        t = "-" if r.time_to_seat_s is None else f"{r.time_to_seat_s:.2f}"
        print(f"{r.clearance_mm:>15g} {str(r.seated):>7} {t:>9} {1000 * r.depth_m:>11.2f} {r.max_tilt_deg:>11.2f} "
              f"{r.max_push_n:>9.1f}")
    seated = [r.clearance_mm for r in rows if r.seated]
    print(f"floor: the smallest clearance that seated: {min(seated):g} mm" if seated else "floor: none seated")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"rows": [asdict(r) for r in rows], "floor_mm": min(seated) if seated else None}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
