"""Is the balls' motion between a sample's two frames visible in what the model gets: pixels and VQ codes?

For each sighting of a ball (red or blue, by colour) in a camera's current frame and its earlier frame, the
ball's pixel displacement between the two, and whether the image code of the patch that holds the ball differs
between them. Run: ``python docs/policy3d/motion_visibility.py --data DATA/shard_0001.npz --checkpoint
policy/checkpoints/mmact_3d.pt`` (frames as ``scenarios.collect`` stores them: views = cameras x frames).
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from policy.bundle import PolicyBundle


def centroid_px(image: np.ndarray, channel: int) -> np.ndarray | None:
    """Pixel centroid (x, y) of the strongly ``channel``-coloured pixels (a ball), None when fewer than 3."""
    x = image.astype(int)
    others = [c for c in range(3) if c != channel]
    mask = (x[..., channel] > 120) & (x[..., channel] > x[..., others[0]] + 60) & (x[..., channel] > x[..., others[1]] + 60)
    if mask.sum() < 3:
        return None
    ys, xs = np.nonzero(mask)
    return np.array([xs.mean(), ys.mean()])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, help="one shard (.npz) of scenarios.collect with two frames per camera")
    ap.add_argument("--checkpoint", default="policy/checkpoints/mmact_3d.pt")
    ap.add_argument("--samples", type=int, default=300)
    args = ap.parse_args()
    torch.set_num_threads(1)
    bundle = PolicyBundle.load(args.checkpoint)
    images = np.load(args.data, allow_pickle=True)["images"][: args.samples]
    n_cam = bundle.n_cameras
    if images.shape[1] != 2 * n_cam:
        raise SystemExit(f"need {2 * n_cam} views (cameras x 2 frames) per sample, got {images.shape[1]}")
    codes = np.asarray(bundle.image_codes(images)).reshape(len(images), images.shape[1], -1)
    grid = int(round(np.sqrt(codes.shape[-1])))
    patch = images.shape[2] // grid
    disp, changed = [], []
    for i in range(len(images)):
        for cam in range(n_cam):
            for channel in (0, 2):  # the red and the blue ball
                now, before = centroid_px(images[i, cam], channel), centroid_px(images[i, cam + n_cam], channel)
                if now is None or before is None:
                    continue
                disp.append(float(np.linalg.norm(now - before)))
                cell = (int(now[1]) // patch) * grid + int(now[0]) // patch
                changed.append(bool(codes[i, cam, cell] != codes[i, cam + n_cam, cell]))
    disp, changed = np.array(disp), np.array(changed)
    print(f"{len(disp)} ball sightings in {len(images)} samples; image codes on a {grid} x {grid} grid ({patch} px patches)")
    print("ball displacement between the frames [px]: median %.2f, p75 %.2f, p90 %.2f, max %.2f"
          % tuple(np.percentile(disp, [50, 75, 90, 100])))
    for lo, hi in [(0.0, 0.5), (0.5, 1.5), (1.5, 3.0), (3.0, np.inf)]:
        sel = (disp >= lo) & (disp < hi)
        if sel.any():
            print(f"  {lo:g}-{hi:g} px: {sel.sum()} sightings; the code of the ball's patch differs between the frames in "
                  f"{changed[sel].mean():.0%}")


if __name__ == "__main__":
    main()
