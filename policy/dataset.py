"""Reads the dataset written by ``python -m scenarios.collect`` (format in the issue / README).

A directory with ``meta.json`` and shards ``shard_XXXX.npz``; each shard holds N_i samples of
``images (N,V,H,W,3) uint8``, ``future_images (N,C,H,W,3)``, ``q_rad (N,7)``, ``actions (N,16,7)``
(float, not quantized), ``instructions``, ``questions``, ``answers`` (str), ``target_index (N,)``,
``target_pos_m (N,3)`` and, collected since issue 25, ``target_prev_pos_m (N,3)`` (the instructed ball where the
earlier frame was taken; the current position when there is none). Every problem is reported with the file and field it concerns.

Views: ``C = len(camera_names)`` cameras and, when ``meta.json`` has ``frame_offsets_s`` (e.g. ``[0.0, -0.1]``: the
frame of the observation and one 0.1 s earlier), ``V = C x len(frame_offsets_s)`` frames ordered frame-major
(``[cam0@0, cam1@0, cam0@-0.1, cam1@-0.1]``); without it ``V = C`` (one frame). The future frame (``<|t2i|>``) is
one per camera.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

META_KEYS = ("image_size_px", "camera_names", "chunk_horizon", "chunk_dt_s", "action_bounds", "action_bins", "future_dt_s")
SHARD_FIELDS = (
    "images", "future_images", "q_rad", "actions", "instructions", "questions", "answers", "target_index", "target_pos_m",
)
#: fields a shard may hold (collected since issue 25): the instructed ball where the earlier frame was taken
OPTIONAL_FIELDS = ("target_prev_pos_m",)


class DatasetError(ValueError):
    """The dataset directory does not match the expected format."""


def read_meta(path: str | Path) -> dict[str, Any]:
    path = Path(path)
    meta_path = path / "meta.json"
    if not meta_path.is_file():
        raise DatasetError(f"{path}: no meta.json (is this a directory written by scenarios.collect?)")
    try:
        meta = json.loads(meta_path.read_text())
    except json.JSONDecodeError as e:
        raise DatasetError(f"{meta_path}: not valid JSON: {e}") from None
    missing = [k for k in META_KEYS if k not in meta]
    if missing:
        raise DatasetError(f"{meta_path}: missing keys {missing}")
    offsets = meta.setdefault("frame_offsets_s", [0.0])
    if (not isinstance(offsets, list) or not offsets or not all(isinstance(x, (int, float)) for x in offsets)
            or offsets[0] != 0 or any(x >= 0 for x in offsets[1:])):
        raise DatasetError(f"{meta_path}: frame_offsets_s must be a list starting with 0 followed by negative "
                           f"offsets (s), got {offsets!r}")
    b = meta["action_bounds"]
    if len(b.get("low", [])) != 7 or len(b.get("high", [])) != 7:
        raise DatasetError(f"{meta_path}: action_bounds need 7 'low' and 7 'high' values")
    return meta


def shard_paths(path: str | Path) -> list[Path]:
    shards = sorted(Path(path).glob("shard_*.npz"))
    if not shards:
        raise DatasetError(f"{path}: no shard_XXXX.npz files")
    return shards


def read_metas(paths: str | Path | list[str | Path]) -> dict[str, Any]:
    """The common ``meta.json`` of one or several dataset directories (trained on together).

    The directories must agree on every field that fixes the token layout (image size, cameras, chunk
    horizon and spacing, action bounds and bins, future frame offset); the first one's meta is returned,
    with ``n_samples`` summed."""
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    if not paths:
        raise DatasetError("no dataset directory given")
    metas = [read_meta(p) for p in paths]
    for p, m in zip(paths[1:], metas[1:]):
        for k in (*META_KEYS, "frame_offsets_s"):
            if m[k] != metas[0][k]:
                raise DatasetError(f"{p}: meta.json {k}={m[k]!r} differs from {paths[0]}'s {metas[0][k]!r}")
    meta = dict(metas[0])
    if all("n_samples" in m for m in metas):
        meta["n_samples"] = sum(int(m["n_samples"]) for m in metas)
    return meta


def dataset_shards(paths: str | Path | list[str | Path]) -> list[tuple[int, Path, dict[str, Any]]]:
    """Every shard of one or several dataset directories as ``(directory index, shard path, that directory's meta)``."""
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    out = []
    for k, p in enumerate(paths):
        meta = read_meta(p)
        out += [(k, s, meta) for s in shard_paths(p)]
    return out


def read_shard(shard: Path, meta: dict[str, Any]) -> dict[str, np.ndarray]:
    """One shard as a dict of arrays, shapes and dtypes checked against ``meta``."""
    try:
        with np.load(shard, allow_pickle=False) as z:
            missing = [f for f in SHARD_FIELDS if f not in z.files]
            if missing:
                raise DatasetError(f"{shard}: missing fields {missing}")
            data = {f: z[f] for f in SHARD_FIELDS}
            data.update({f: z[f] for f in OPTIONAL_FIELDS if f in z.files})
    except DatasetError:
        raise
    except Exception as e:  # zip / pickle / truncation errors
        raise DatasetError(f"{shard}: unreadable shard: {type(e).__name__}: {e}") from None
    n = len(data["images"])
    s, c, h = meta["image_size_px"], len(meta["camera_names"]), meta["chunk_horizon"]
    v = c * len(meta.get("frame_offsets_s", [0.0]))
    expect = {
        "images": (n, v, s, s, 3), "future_images": (n, c, s, s, 3), "q_rad": (n, 7), "actions": (n, h, 7),
        "instructions": (n,), "questions": (n,), "answers": (n,), "target_index": (n,), "target_pos_m": (n, 3),
        "target_prev_pos_m": (n, 3),
    }
    for f, shape in expect.items():
        if f in data and data[f].shape != shape:
            raise DatasetError(f"{shard}: field {f!r} has shape {data[f].shape}, expected {shape}")
    for f in ("images", "future_images"):
        if data[f].dtype != np.uint8:
            raise DatasetError(f"{shard}: field {f!r} must be uint8, got {data[f].dtype}")
    for f in ("instructions", "questions", "answers"):
        if data[f].dtype.kind not in "UO":
            raise DatasetError(f"{shard}: field {f!r} must hold strings, got {data[f].dtype}")
        data[f] = data[f].astype(str)
    for f in ("q_rad", "actions", "target_pos_m", *OPTIONAL_FIELDS):
        if f in data and not np.all(np.isfinite(data[f])):
            raise DatasetError(f"{shard}: field {f!r} contains NaN or inf")
    return data


@dataclass
class PolicyDataset:
    """All shards concatenated in memory (images as uint8)."""

    meta: dict[str, Any]
    data: dict[str, np.ndarray]

    @classmethod
    def load(cls, path: str | Path, fields: tuple[str, ...] = SHARD_FIELDS) -> "PolicyDataset":
        meta = read_meta(path)
        parts = [read_shard(s, meta) for s in shard_paths(path)]
        data = {f: np.concatenate([p[f] for p in parts]) for f in fields}
        n = len(data[fields[0]])
        if "n_samples" in meta and meta["n_samples"] != n:
            raise DatasetError(f"{path}: meta.json says n_samples={meta['n_samples']} but the shards hold {n}")
        return cls(meta=meta, data=data)

    def __len__(self) -> int:
        return len(next(iter(self.data.values())))


def split_indices(n: int, val_fraction: float, split_seed: int, max_val: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic (train, held-out) index split; the same for every stage and training seed."""
    perm = np.random.default_rng(split_seed).permutation(n)
    n_val = min(max_val, int(round(n * val_fraction)))
    if n >= 2:
        n_val = max(1, min(n_val, n - 1))
    else:
        n_val = 0
    return np.sort(perm[n_val:]), np.sort(perm[:n_val])
