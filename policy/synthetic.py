"""Synthetic dataset in the exact ``scenarios.collect`` format, for tests and architecture sanity checks.

A top-down "camera" sees a grey table with 2-3 coloured discs (radius 3-4 px). The workspace maps
linearly to pixels (x in [0.3, 0.7] m -> rows, far at the top; y in [-0.35, 0.35] m -> columns,
8 px margin), so 1 px is 5 mm in x and 8.75 mm in y. The expert chunk moves the TCP from a start
point (a fixed function of ``q_rad``) to the named disc; the future frame shows a dark "gripper"
square over that disc. Questions: "where is the <c> ball?" (left/center/right) and "how many balls
are there?" (two/three).

``python -m policy.synthetic OUT --n 2000`` writes one.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

COLOURS: dict[str, tuple[int, int, int]] = {
    "red": (210, 40, 40), "green": (40, 180, 60), "blue": (40, 70, 215), "yellow": (225, 205, 40),
}
X_RANGE_M = (0.3, 0.7)
Y_RANGE_M = (-0.35, 0.35)
BALL_Z_M = 0.12
MARGIN_PX = 8
ACTION_LOW = (0.3, -0.35, 0.1, -0.5, -0.5, -0.5, 0.0)
ACTION_HIGH = (0.7, 0.35, 0.5, 0.5, 0.5, 0.5, 0.08)


def world_to_pixel(x_m: float, y_m: float, size_px: int) -> tuple[float, float]:
    """(row, col) in pixels of a world point on the table."""
    span = size_px - 2 * MARGIN_PX
    row = MARGIN_PX + (X_RANGE_M[1] - x_m) / (X_RANGE_M[1] - X_RANGE_M[0]) * span
    col = MARGIN_PX + (y_m - Y_RANGE_M[0]) / (Y_RANGE_M[1] - Y_RANGE_M[0]) * span
    return row, col


def _draw_disc(img: np.ndarray, row: float, col: float, r: float, colour) -> None:
    s = img.shape[0]
    yy, xx = np.mgrid[0:s, 0:s]
    img[(yy + 0.5 - row) ** 2 + (xx + 0.5 - col) ** 2 <= r * r] = colour


def make_samples(n: int, size_px: int = 96, n_views: int = 1, horizon: int = 16, seed: int = 0,
                 n_balls: tuple[int, int] = (2, 3)) -> dict[str, np.ndarray]:
    """``n`` samples; each scene has ``n_balls[0]..n_balls[1]`` discs of distinct colours."""
    rng = np.random.default_rng(seed)
    names = list(COLOURS)
    out = {
        "images": np.zeros((n, n_views, size_px, size_px, 3), np.uint8),
        "future_images": np.zeros((n, n_views, size_px, size_px, 3), np.uint8),
        "q_rad": np.zeros((n, 7), np.float32), "actions": np.zeros((n, horizon, 7), np.float32),
        "target_index": np.zeros(n, np.int64), "target_pos_m": np.zeros((n, 3), np.float32),
    }
    instr, quest, ans = [], [], []
    for i in range(n):
        k = int(rng.integers(n_balls[0], n_balls[1] + 1))
        colours = rng.choice(names, size=k, replace=False)
        pos: list[tuple[float, float]] = []
        while len(pos) < k:
            p = (rng.uniform(0.34, 0.66), rng.uniform(-0.31, 0.31))
            if all(np.hypot(*np.subtract(world_to_pixel(*p, size_px), world_to_pixel(*o, size_px))) > 12 for o in pos):
                pos.append(p)
        radii = rng.uniform(3.0, 4.0, size=k)
        t = int(rng.integers(k))
        base = rng.uniform(100, 160)
        grad = rng.uniform(-20, 20)
        for v in range(n_views):
            img = np.full((size_px, size_px, 3), base, np.float64)
            img += grad * np.linspace(-1, 1, size_px)[:, None, None]
            img += rng.normal(0, 4, img.shape)
            img = np.clip(img, 0, 255).astype(np.uint8)
            for j in range(k):
                _draw_disc(img, *world_to_pixel(*pos[j], size_px), radii[j], COLOURS[colours[j]])
            fut = img.copy()
            r, c = world_to_pixel(*pos[t], size_px)
            fut[int(r) - 3 : int(r) + 4, int(c) - 3 : int(c) + 4] = (30, 30, 30)
            if v % 2 == 1:
                img, fut = img[:, ::-1], fut[:, ::-1]
            if v >= 2:
                img, fut = img[::-1], fut[::-1]
            out["images"][i, v], out["future_images"][i, v] = img, fut
        q = rng.uniform(-1.0, 1.0, size=7).astype(np.float32)
        q[3] = rng.uniform(-2.5, -1.0)
        q[5] = rng.uniform(0.5, 2.5)
        start = np.array([0.5 + 0.15 * np.sin(q[0]), 0.25 * np.sin(q[1]), 0.3 + 0.1 * np.sin(q[2])])
        target = np.array([pos[t][0], pos[t][1], BALL_Z_M])
        s = np.minimum(1.0, (np.arange(horizon) + 1) / 12.0)
        s = s * s * (3 - 2 * s)
        out["actions"][i, :, :3] = start + (target - start) * s[:, None]
        out["actions"][i, :, 6] = 0.04
        out["q_rad"][i] = q
        out["target_index"][i] = t
        out["target_pos_m"][i] = target
        verb, noun = ["reach", "touch", "move to"][i % 3], ["ball", "sphere"][int(rng.integers(2))]
        instr.append(f"{verb} the {colours[t]} {noun}")
        if rng.random() < 0.75:
            j = int(rng.integers(k))
            y = pos[j][1]
            quest.append(f"where is the {colours[j]} ball?")
            ans.append("left" if y < -0.1 else "right" if y > 0.1 else "center")
        else:
            quest.append("how many balls are there?")
            ans.append({1: "one", 2: "two", 3: "three", 4: "four"}[k])
    out["instructions"], out["questions"], out["answers"] = np.array(instr), np.array(quest), np.array(ans)
    return out


def write_synthetic_dataset(
    path: str | Path, n_samples: int, n_views: int = 1, shard_size: int = 1000, size_px: int = 96, seed: int = 0,
    n_balls: tuple[int, int] = (2, 3),
) -> Path:
    """Write ``meta.json`` + ``shard_XXXX.npz`` with ``n_samples`` synthetic samples; returns the path."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    horizon = 16
    meta = {
        "image_size_px": size_px, "camera_names": [f"cam{v}" if v else "front" for v in range(n_views)],
        "chunk_horizon": horizon, "chunk_dt_s": 0.1,
        "action_bounds": {"low": list(ACTION_LOW), "high": list(ACTION_HIGH)},
        "action_bins": 2048, "future_dt_s": 0.5, "n_samples": n_samples, "generator": "policy.synthetic",
    }
    for s, start in enumerate(range(0, n_samples, shard_size)):
        m = min(shard_size, n_samples - start)
        np.savez_compressed(path / f"shard_{s:04d}.npz", **make_samples(m, size_px, n_views, horizon, seed=seed * 100003 + s,
                                                                         n_balls=n_balls))
    (path / "meta.json").write_text(json.dumps(meta, indent=1))
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--views", type=int, default=1)
    ap.add_argument("--shard-size", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--balls", default="2,3", help="min,max discs per scene (1,1 = pure localisation, no colour binding)")
    a = ap.parse_args()
    lo, hi = (int(x) for x in a.balls.split(","))
    print(write_synthetic_dataset(a.out, a.n, a.views, a.shard_size, seed=a.seed, n_balls=(lo, hi)))


if __name__ == "__main__":
    main()
