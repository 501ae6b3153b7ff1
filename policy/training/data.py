"""The data of a stage-1/2 run: its meta (from ``--data`` or ``--tokens-cache``), its token arrays, the sampling
weights of its directories, and the held-out subset the evaluation reads."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

from policy.bundle import PolicyBundle
from policy.dataset import DatasetError, read_metas
from policy.token_cache import TokenCacheError, load_token_cache, read_header, save_token_cache, tokenizer_fingerprint
from policy.training.tokenize import load_tokenized


def token_caches(args) -> list[str]:
    """The ``--tokens-cache`` file names of ``args`` (one string or a list; none: ``[]``)."""
    cache = getattr(args, "tokens_cache", None)
    return [cache] if isinstance(cache, str) else list(cache or [])


def training_tokens(bundle: PolicyBundle, args) -> dict[str, np.ndarray]:
    """The token arrays of ``--data``, read from the ``--tokens-cache`` file(s) when they exist (and were made by this
    bundle's tokenizers; several are concatenated, each keeping its directories' ``source`` indices in the order of
    ``args.data``), else tokenized from the frames (and written to the one ``--tokens-cache`` when one is named)."""
    caches = token_caches(args)
    if caches and all(Path(c).is_file() for c in caches):
        parts, n_dirs = [], 0
        for c in caches:
            try:
                data, header = load_token_cache(c, bundle)
            except TokenCacheError as exc:
                raise SystemExit(f"--tokens-cache: {exc}") from None
            data["source"] = (data["source"].astype(np.int64) + n_dirs).astype(np.int16)
            n_dirs += len(header["data_paths"])
            parts.append(data)
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if len(parts) > 1 else parts[0]
    data = load_tokenized(bundle, args.data, not args.no_progress)
    if caches:
        save_token_cache(caches[0], data, read_metas(args.data), tokenizer_fingerprint(bundle), list(args.data))
        print(f"tokens of {len(data['img'])} samples cached in {caches[0]}", file=sys.stderr)
    return data


def resolve_data(args) -> dict[str, Any]:
    """The data's meta from ``--data`` or from existing ``--tokens-cache`` files (which then fill ``args.data``: the
    directories of every cache, in order)."""
    caches = token_caches(args)
    if caches and args.stage == 0:
        raise SystemExit("--tokens-cache is for stages 1/2 (stage 0 trains the image tokenizer on the frames themselves)")
    if caches and all(Path(c).is_file() for c in caches):
        return _meta_from_caches(args, caches)
    if len(caches) > 1:
        missing = [c for c in caches if not Path(c).is_file()]
        raise SystemExit(f"--tokens-cache: {missing} do not exist (only a single cache is written from --data)")
    if not args.data:
        raise SystemExit("--data is required (or --tokens-cache naming existing caches, stages 1/2)")
    try:
        return read_metas(args.data)
    except DatasetError as exc:
        raise SystemExit(f"--data: {exc}") from None


def _meta_from_caches(args, caches: list[str]) -> dict[str, Any]:
    """The meta of existing caches (they must agree on the token layout); sets ``args.data`` to their directories."""
    headers = []
    for c in caches:
        try:
            headers.append(read_header(c))
        except TokenCacheError as exc:
            raise SystemExit(f"--tokens-cache: {exc}") from None
    paths = [str(Path(d)) for h in headers for d in h["data_paths"]]
    if args.data and [str(Path(d)) for d in args.data] != paths:
        raise SystemExit(f"--tokens-cache {' '.join(caches)} holds the tokens of {paths}, not of --data "
                         f"{args.data}; leave --data out or name another cache file")
    meta = dict(headers[0]["meta"])
    for c, h in zip(caches[1:], headers[1:]):
        for k in ("image_size_px", "chunk_horizon", "chunk_dt_s", "action_bounds", "action_bins", "frame_offsets_s"):
            if h["meta"].get(k) != meta.get(k):
                raise SystemExit(f"--tokens-cache {c}: its data's {k}={h['meta'].get(k)!r} differs from "
                                 f"{caches[0]}'s {meta.get(k)!r}")
    meta["n_samples"] = sum(int(h["n_samples"]) for h in headers)
    args.data = paths
    return meta


def check_data_weights(weights: list[float] | None, n_dirs: int) -> None:
    """``--data-weights``: one finite weight >= 0 per ``--data`` directory (checked before any data is read)."""
    if weights is None:
        return
    if len(weights) != n_dirs:
        raise SystemExit(f"--data-weights: got {len(weights)} weights for {n_dirs} --data directories")
    w = np.asarray(weights, dtype=np.float64)
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise SystemExit(f"--data-weights must be finite and >= 0, got {list(weights)}")


def sampling_probabilities(source: np.ndarray, weights: list[float] | None, n_dirs: int) -> np.ndarray | None:
    """Per-sample draw probabilities from one weight per dataset directory (None: uniform over samples).

    A sample of a directory with weight ``w`` is drawn ``w`` times as often as a sample of weight 1, e.g. to
    favour the newest DAgger round over the bulk of the expert demonstrations."""
    if weights is None:
        return None
    check_data_weights(weights, n_dirs)
    p = np.asarray(weights, dtype=np.float64)[source]
    if p.sum() <= 0:
        raise SystemExit(f"--data-weights {list(weights)} give every training sample weight 0")
    return p / p.sum()


def eval_subset(val_idx: np.ndarray, n: int, seed: int) -> np.ndarray:
    """A seeded random subset of the held-out indices, so every dataset directory is represented in proportion
    (the held-out indices are sorted: their first ``n`` would all come from the first directory)."""
    if len(val_idx) <= n:
        return val_idx
    return np.sort(np.random.default_rng(seed).choice(val_idx, size=n, replace=False))
