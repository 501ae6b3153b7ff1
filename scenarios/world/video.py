"""Write rendered frames to an MP4 file (imageio + its ffmpeg plugin)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_mp4(frames: list[np.ndarray], path: str | Path, fps: float) -> Path:
    """Write ``frames`` (each ``(H, W, 3)`` uint8, all the same shape) to an H.264 MP4 at ``path``.

    A ``(V, H, W, 3)`` frame from ``SimWorld.render`` is tiled side by side. Returns the path.

    Raises:
        ValueError: empty ``frames``, non-positive ``fps``, or frames of different shapes.
    """
    if len(frames) == 0:
        raise ValueError(f"write_mp4: no frames to write to {path}")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"write_mp4: fps must be > 0, got {fps!r}")
    import imageio.v2 as imageio

    def _as_image(frame: np.ndarray) -> np.ndarray:
        arr = np.asarray(frame)
        if arr.ndim == 4:  # (V, H, W, 3): views side by side
            arr = np.concatenate(list(arr), axis=1)
        if arr.ndim != 3 or arr.shape[2] != 3:
            raise ValueError(f"write_mp4: frames must be (H, W, 3) or (V, H, W, 3), got shape {np.asarray(frame).shape}")
        arr = arr.astype(np.uint8, copy=False)
        # yuv420p needs even sizes: repeat the last row/column if needed
        pad = ((0, arr.shape[0] % 2), (0, arr.shape[1] % 2), (0, 0))
        return np.pad(arr, pad, mode="edge") if any(p[1] for p in pad) else arr

    images = [_as_image(f) for f in frames]
    shape = images[0].shape
    for i, img in enumerate(images):
        if img.shape != shape:
            raise ValueError(f"write_mp4: frame {i} has shape {img.shape}, frame 0 has {shape}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # macro_block_size=1: keep sizes that are not multiples of 16 (e.g. 96x288) untouched
    with imageio.get_writer(path, format="FFMPEG", mode="I", fps=float(fps), codec="libx264",
                            pixelformat="yuv420p", macro_block_size=1) as writer:
        for img in images:
            writer.append_data(img)
    return path
