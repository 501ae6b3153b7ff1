"""Feature statistics as LeRobot's ``meta/stats.json`` holds them: min, max, mean, std, count and the quantiles
q01, q10, q50, q90, q99, per dimension of a vector feature and per channel of a camera (pixels scaled to [0, 1],
shape ``(3, 1, 1)``), computed with numpy; episodes are pooled by :func:`aggregate` (count-weighted mean and
variance, extreme min and max, count-weighted quantiles, as LeRobot's ``aggregate_stats`` does).
"""

from __future__ import annotations

import numpy as np

from mmact_ctrl.datasets.layout import QUANTILES

#: a camera's frames sampled for its stats per episode (LeRobot samples too): at most this many, evenly spaced
IMAGE_SAMPLES_PER_EPISODE = 100


def _quantile_keys() -> list[str]:
    return [f"q{int(round(q * 100)):02d}" for q in QUANTILES]


def vector_stats(values: np.ndarray) -> dict[str, np.ndarray]:
    """Stats of ``values`` ``(N, D)`` (or ``(N,)``) over the frames: arrays of shape ``(D,)``; count ``(1,)``."""
    x = np.asarray(values, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    out = {"min": x.min(axis=0), "max": x.max(axis=0), "mean": x.mean(axis=0), "std": x.std(axis=0),
           "count": np.array([x.shape[0]], dtype=np.int64)}
    for key, q in zip(_quantile_keys(), QUANTILES):
        out[key] = np.quantile(x, q, axis=0)
    return out


def sample_indices(n: int, at_most: int = IMAGE_SAMPLES_PER_EPISODE) -> np.ndarray:
    """At most ``at_most`` frame indices of ``n``, evenly spaced, the first and the last included."""
    if n <= at_most:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, at_most)).astype(int))


def image_stats(frames: np.ndarray) -> dict[str, np.ndarray]:
    """Stats of camera frames ``(N, H, W, 3)`` uint8 per channel, pixels in [0, 1]: arrays of shape ``(3, 1, 1)``;
    ``count`` is the number of frames sampled (:func:`sample_indices`)."""
    idx = sample_indices(len(frames))
    px = frames[idx].reshape(-1, 3).astype(np.float64) / 255.0
    s = vector_stats(px)
    out = {k: v.reshape(3, 1, 1) for k, v in s.items() if k != "count"}
    out["count"] = np.array([len(idx)], dtype=np.int64)
    return out


def aggregate(per_episode: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Pool one feature's episode stats: count-weighted mean, the pooled variance (within + between episodes),
    the extreme min and max, the count-weighted mean of each quantile (LeRobot's approximation: the pooled data's
    quantiles are not kept), the summed count."""
    counts = np.array([float(s["count"][0]) for s in per_episode])
    w = counts / counts.sum()
    shape = per_episode[0]["mean"].shape
    wb = w.reshape((-1,) + (1,) * len(shape))
    means = np.stack([s["mean"] for s in per_episode])
    mean = (wb * means).sum(axis=0)
    var = (wb * (np.stack([s["std"] for s in per_episode]) ** 2 + (means - mean) ** 2)).sum(axis=0)
    out = {"min": np.min(np.stack([s["min"] for s in per_episode]), axis=0),
           "max": np.max(np.stack([s["max"] for s in per_episode]), axis=0),
           "mean": mean, "std": np.sqrt(var), "count": np.array([int(counts.sum())], dtype=np.int64)}
    for key in _quantile_keys():
        out[key] = (wb * np.stack([s[key] for s in per_episode])).sum(axis=0)
    return out


def to_json(stats: dict[str, dict[str, np.ndarray]]) -> dict:
    """``{feature: {stat: nested list}}`` for ``stats.json``."""
    return {f: {k: np.asarray(v).tolist() for k, v in s.items()} for f, s in stats.items()}
