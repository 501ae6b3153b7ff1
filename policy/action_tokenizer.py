"""Uniform-bin action tokenizer (MM-ACT style).

A 7-dim action is ``[x_m, y_m, z_m, rx_rad, ry_rad, rz_rad, gripper_m]``: end-effector
position in metres (world frame), orientation as a rotation vector in radians relative
to the nominal grasp orientation, and gripper opening in metres. Each dimension is
normalized to [-1, 1] over configured bounds and cut into ``bins`` uniform bins.
Dequantization returns bin centres, so the round-trip error is at most half a bin
(``(high - low) / (2 * bins)``) for in-range values. Out-of-range values are clipped
(and counted), never wrapped. Tokens are offset into the shared vocabulary by
``token_offset`` (``VocabLayout.action_offset``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

ACTION_DIM = 7
ACTION_NAMES: tuple[str, ...] = ("x_m", "y_m", "z_m", "rx_rad", "ry_rad", "rz_rad", "gripper_m")


@dataclass(frozen=True)
class ActionBounds:
    """Per-dimension ``[low, high]`` of the 7-dim action (units as in ``ACTION_NAMES``)."""

    low: tuple[float, ...] = (0.15, -0.5, 0.0, -1.0, -1.0, -1.0, 0.0)
    high: tuple[float, ...] = (0.85, 0.5, 0.8, 1.0, 1.0, 1.0, 0.08)

    def __post_init__(self) -> None:
        if len(self.low) != ACTION_DIM or len(self.high) != ACTION_DIM:
            raise ValueError(f"ActionBounds need {ACTION_DIM} lows and highs, got {len(self.low)} and {len(self.high)}")
        for i, (lo, hi) in enumerate(zip(self.low, self.high)):
            if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
                raise ValueError(f"ActionBounds dim {i} ({ACTION_NAMES[i]}): need finite low < high, got [{lo}, {hi}]")


@dataclass(frozen=True)
class ActionTokenizer:
    """Quantizes 7-dim actions into ``bins`` uniform bins per dimension.

    Attributes:
        bins: bins per dimension (>= 2). Use no tokenizer at all for "no quantization".
        bounds: normalization bounds.
        token_offset: id of bin 0 in the shared vocabulary.
    """

    bins: int = 2048
    bounds: ActionBounds = field(default_factory=ActionBounds)
    token_offset: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.bins, (int, np.integer)) or self.bins < 2:
            raise ValueError(f"ActionTokenizer.bins must be an int >= 2, got {self.bins!r}")
        if self.token_offset < 0:
            raise ValueError(f"ActionTokenizer.token_offset must be >= 0, got {self.token_offset}")

    @property
    def low(self) -> np.ndarray:
        return np.asarray(self.bounds.low, dtype=np.float64)

    @property
    def high(self) -> np.ndarray:
        return np.asarray(self.bounds.high, dtype=np.float64)

    @property
    def bin_width(self) -> np.ndarray:
        """Width of one bin per dimension, in that dimension's unit."""
        return (self.high - self.low) / self.bins

    def encode(self, actions: np.ndarray) -> tuple[np.ndarray, int]:
        """Actions ``(..., 7)`` -> (tokens ``(..., 7)`` int64 in the shared vocabulary, n_clipped).

        ``n_clipped`` counts scalar values that lay outside the bounds and were clipped.
        """
        a = np.asarray(actions, dtype=np.float64)
        if a.shape[-1:] != (ACTION_DIM,):
            raise ValueError(f"actions must have shape (..., {ACTION_DIM}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError("actions contain NaN or inf")
        n_clipped = int(np.count_nonzero((a < self.low) | (a > self.high)))
        unit = (np.clip(a, self.low, self.high) - self.low) / (self.high - self.low)  # [0, 1]
        idx = np.minimum(np.floor(unit * self.bins), self.bins - 1).astype(np.int64)
        return idx + int(self.token_offset), n_clipped

    def decode(self, tokens: np.ndarray) -> np.ndarray:
        """Tokens ``(..., 7)`` -> bin-centre actions ``(..., 7)``. Raises on a token outside the action range."""
        t = np.asarray(tokens)
        if t.shape[-1:] != (ACTION_DIM,):
            raise ValueError(f"action tokens must have shape (..., {ACTION_DIM}), got {t.shape}")
        if not np.issubdtype(t.dtype, np.integer):
            raise TypeError(f"action tokens must be integers, got dtype {t.dtype}")
        idx = t.astype(np.int64) - int(self.token_offset)
        bad = (idx < 0) | (idx >= self.bins)
        if np.any(bad):
            first = int(t[bad].flat[0])
            raise ValueError(
                f"token {first} is outside the action range [{self.token_offset}, {self.token_offset + self.bins})"
            )
        return self.decode_fractional(idx)

    def decode_fractional(self, bin_index: np.ndarray) -> np.ndarray:
        """Fractional bin indices ``(..., 7)`` (0-based, e.g. from ``policy.decoding.expected_bins``) ->
        actions ``(..., 7)``; integer indices give the bin centres, as ``decode`` does."""
        b = np.asarray(bin_index, dtype=np.float64)
        if b.shape[-1:] != (ACTION_DIM,):
            raise ValueError(f"bin indices must have shape (..., {ACTION_DIM}), got {b.shape}")
        bad = ~np.isfinite(b) | (b < 0) | (b > self.bins - 1)
        if np.any(bad):
            raise ValueError(f"bin indices must be finite and in [0, {self.bins - 1}], got {float(b[bad].flat[0])}")
        return self.low + (b + 0.5) * self.bin_width

    def roundtrip(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Quantize then dequantize: (dequantized actions, tokens, n_clipped)."""
        tokens, n_clipped = self.encode(actions)
        return self.decode(tokens), tokens, n_clipped
