"""Where the balls are in each frame: a colour-centroid detector and its tokens (issue 25, lever 2).

The policy is given, per view (camera x frame) and per ball colour, the ball's sub-pixel image position, computed
here from the very RGB frame it already gets (never from the simulator's ground truth):

- a pixel belongs to a colour when that colour's channel dominates: ``c - max(other two) > min_chroma * c`` and
  ``c > min_value`` (0..1 scale). Shading keeps the ratio, so the lit and the shaded side of a ball both count; the
  brown table (r - g = 0.24 r), the grey arm, the sky and the dark fingers do not.
- its position is the centroid of those pixels, ``(u, v)`` = (column, row) in pixels with pixel centres at +0.5
  (so ``0 <= u, v <= W``), and its size the pixel count; fewer than ``min_pixels`` pixels is "not seen" (hidden
  by the arm or the other ball, or out of the frame).
- ``BallTokenizer`` cuts ``u`` and ``v`` into the state bins (``bins`` uniform bins over ``[0, W]`` px, the action
  range of the shared vocabulary, as the joint angles are); a ball not seen gets ``<|pad|>``.

On a real robot the same input needs a detector that finds each coloured object in each camera frame (here a
colour threshold suffices: uniformly coloured balls on a plain scene); a partly hidden ball biases the centroid
toward its visible part, as a real detector's box would.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

#: dominant RGB channel of each colour name the detector knows
COLOR_CHANNEL: dict[str, int] = {"red": 0, "green": 1, "blue": 2}


@dataclass(frozen=True)
class BallDetectorConfig:
    """Attributes:
    colors: the ball colours, in token order (the scene's ``TARGET_COLORS``: red, blue).
    min_chroma: a pixel is of a colour when its channel exceeds both others by this share of its own value.
    min_value: ... and the channel itself exceeds this (0..1), so near-black pixels do not count.
    min_pixels: fewer pixels than this: the ball is not seen in that frame.
    """

    colors: tuple[str, ...] = ("red", "blue")
    min_chroma: float = 0.45
    min_value: float = 0.12
    min_pixels: int = 3

    def __post_init__(self) -> None:
        if not self.colors or any(c not in COLOR_CHANNEL for c in self.colors):
            raise ValueError(f"BallDetectorConfig.colors must name colours of {sorted(COLOR_CHANNEL)}, got {self.colors!r}")
        if not 0.0 < self.min_chroma < 1.0:
            raise ValueError(f"BallDetectorConfig.min_chroma must be in (0, 1), got {self.min_chroma}")
        if not 0.0 <= self.min_value < 1.0:
            raise ValueError(f"BallDetectorConfig.min_value must be in [0, 1), got {self.min_value}")
        if int(self.min_pixels) != self.min_pixels or self.min_pixels < 1:
            raise ValueError(f"BallDetectorConfig.min_pixels must be an int >= 1, got {self.min_pixels}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "BallDetectorConfig":
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in data.items()})


def _check_images(images: np.ndarray) -> np.ndarray:
    img = np.asarray(images)
    if img.dtype != np.uint8 or img.ndim < 3 or img.shape[-1] != 3:
        raise ValueError(f"images must be uint8 (..., H, W, 3), got {img.shape} {img.dtype}")
    return img


def color_masks(images: np.ndarray, cfg: BallDetectorConfig = BallDetectorConfig()) -> np.ndarray:
    """bool ``(..., C, H, W)``: the pixels of each colour of ``cfg.colors`` in uint8 frames ``(..., H, W, 3)``."""
    img = _check_images(images)
    x = img.astype(np.float32) / 255.0
    out = []
    for name in cfg.colors:
        c = COLOR_CHANNEL[name]
        main = x[..., c]
        others = np.maximum(x[..., (c + 1) % 3], x[..., (c + 2) % 3])
        out.append((main > cfg.min_value) & (main - others > cfg.min_chroma * main))
    return np.stack(out, axis=-3)


def detect_balls(images: np.ndarray, cfg: BallDetectorConfig = BallDetectorConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Colour centroids of uint8 frames ``(..., H, W, 3)``.

    Returns ``(uv_px (..., C, 2) float64, n_px (..., C) int64)``: per colour of ``cfg.colors`` the centroid
    ``(u, v)`` (column, row; pixel centres at +0.5) and the pixel count; NaN where fewer than ``min_pixels``.
    """
    img = _check_images(images)
    lead, (h, w) = img.shape[:-3], img.shape[-3:-1]
    masks = color_masks(img.reshape(-1, h, w, 3), cfg)  # (N, C, H, W)
    cols = np.arange(w, dtype=np.float64) + 0.5
    rows = np.arange(h, dtype=np.float64) + 0.5
    uv = np.full((len(masks), len(cfg.colors), 2), np.nan)
    n = np.zeros((len(masks), len(cfg.colors)), dtype=np.int64)
    for j in range(len(cfg.colors)):
        mask = masks[:, j]
        cnt = mask.sum(axis=(1, 2))
        seen = cnt >= cfg.min_pixels
        n[:, j] = cnt
        with np.errstate(invalid="ignore", divide="ignore"):
            u = (mask.sum(axis=1) * cols).sum(-1) / cnt  # column sums weighted by column centres
            v = (mask.sum(axis=2) * rows).sum(-1) / cnt
        uv[seen, j, 0], uv[seen, j, 1] = u[seen], v[seen]
    return uv.reshape(*lead, len(cfg.colors), 2), n.reshape(*lead, len(cfg.colors))


@dataclass(frozen=True)
class BallTokenizer:
    """Image positions (px) <-> tokens of the state bins: ``bins`` uniform bins over ``[0, image_size_px]``.

    Attributes:
        image_size_px: frame width = height the positions are measured in.
        bins: bins per coordinate (the action bins of the shared vocabulary).
        token_offset: id of bin 0 in the shared vocabulary (``VocabLayout.action_offset``).
        absent_id: the token of a ball not seen (``<|pad|>``).
    """

    image_size_px: int
    bins: int
    token_offset: int
    absent_id: int

    def encode(self, uv_px: np.ndarray) -> np.ndarray:
        """``(..., 2)`` positions (NaN = not seen) -> int64 tokens ``(..., 2)``."""
        uv = np.asarray(uv_px, dtype=np.float64)
        seen = np.isfinite(uv)
        unit = np.clip(np.where(seen, uv, 0.0) / self.image_size_px, 0.0, 1.0)
        idx = np.minimum(np.floor(unit * self.bins), self.bins - 1).astype(np.int64)
        return np.where(seen, idx + self.token_offset, self.absent_id)

    def decode(self, tokens: np.ndarray) -> np.ndarray:
        """Tokens -> bin-centre positions (px); NaN for ``absent_id``."""
        t = np.asarray(tokens, dtype=np.int64)
        idx = t - self.token_offset
        ok = (idx >= 0) & (idx < self.bins)
        if np.any(~ok & (t != self.absent_id)):
            raise ValueError(f"ball tokens must be in [{self.token_offset}, {self.token_offset + self.bins}) or the "
                             f"absent id {self.absent_id}")
        return np.where(ok, (idx + 0.5) * self.image_size_px / self.bins, np.nan)
