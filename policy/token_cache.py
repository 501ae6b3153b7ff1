"""A dataset's tokens, cached in one file, so stage 1/2 can train where the frames are not.

Stage 1/2 never look at pixels: ``policy.training.tokenize.load_tokenized`` turns every frame into VQ-VAE codes and
every string and float into token ids before the first step. The cache is that dict of token arrays, written once
(``np.savez_compressed``, no pickles) with the dataset's ``meta.json`` and a fingerprint of the tokenizers that made
it. 12,000 two-camera two-frame samples are 431 MB of frames and about 20 MB of tokens: small enough to carry to an
accelerator machine that has torch but neither the frames nor MuJoCo (``docs/policy3d/device_train.sh``).

    python -m policy.token_cache --data DATA [DATA ...] --checkpoint CKPT --out tokens.npz
    python -m policy.train --tokens-cache tokens.npz --stage 2 --init CKPT --out OUT ...

The fingerprint covers everything that fixes a token id: the image tokenizer's weights, the text tokenizer, the
action and state tokenizers, the ball detector (``policy.ball_detector``: every cache holds each view's ball tokens),
the views (cameras x frame offsets) and the text lengths of the model config. A cache made with other tokenizers is
refused with both fingerprints named, never trained on. Caches of one frozen tokenizer accumulate: the data of each
new collection (a DAgger round) is cached alone and trained on beside the earlier ones (``--tokens-cache A B ...``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from policy.checkpoint import cpu_state, tokenizer_dict, weights_digest

FORMAT = "mmact-ctrl/token-cache"
FORMAT_VERSION = 2  # 2 (issue 25): + ball (the detector's ball tokens per view) and target_prev_pos_m
#: the arrays ``policy.training.tokenize.load_tokenized`` returns (and the cache must hold)
FIELDS = ("img", "fut", "instr", "quest", "answer", "answer_str", "state", "action", "actions_f", "target_pos_m", "source",
          "ball", "target_prev_pos_m")


class TokenCacheError(ValueError):
    """The cache file is unreadable, incomplete, or was made with other tokenizers."""


def tokenizer_fingerprint(bundle) -> str:
    """sha256 over everything that decides a sample's token ids in ``bundle`` (a ``PolicyBundle`` with a model)."""
    h = hashlib.sha256()
    h.update(weights_digest(cpu_state(bundle.image_tokenizer)).encode())
    h.update(bundle.text_tokenizer.to_json().encode())
    cfg = bundle.model_cfg
    layout = {"action": tokenizer_dict(bundle.action_tokenizer), "state": tokenizer_dict(bundle.state_tokenizer),
              "cameras": list(bundle.camera_names), "frame_offsets_s": [float(x) for x in bundle.frame_offsets_s],
              "max_text_len": cfg.max_text_len if cfg else None, "max_answer_len": cfg.max_answer_len if cfg else None,
              "ball_detector": bundle.ball_detector.to_dict()}
    h.update(json.dumps(layout, sort_keys=True, default=str).encode())
    return h.hexdigest()


def save_token_cache(path: str | Path, data: dict[str, np.ndarray], meta: dict[str, Any], fingerprint: str,
                     data_paths: list[str]) -> Path:
    """Write the token arrays with ``meta`` and the tokenizer ``fingerprint``; returns the path."""
    missing = [f for f in FIELDS if f not in data]
    if missing:
        raise TokenCacheError(f"token arrays miss {missing}")
    n = len(data["img"])
    if any(len(data[f]) != n for f in FIELDS):
        raise TokenCacheError(f"token arrays disagree on the sample count: { {f: len(data[f]) for f in FIELDS} }")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = {"format": FORMAT, "format_version": FORMAT_VERSION, "fingerprint": fingerprint, "meta": meta,
              "data_paths": [str(p) for p in data_paths], "n_samples": int(n)}
    arrays = {f: np.asarray(data[f]) for f in FIELDS}
    arrays["answer_str"] = arrays["answer_str"].astype(str)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, __header__=np.array(json.dumps(header, default=float)), **arrays)
    tmp.replace(path)
    return path


def read_header(path: str | Path) -> dict[str, Any]:
    """The cache's header (format, fingerprint, the dataset's meta, its paths, sample count)."""
    path = Path(path)
    if not path.is_file():
        raise TokenCacheError(f"{path}: no such token cache (make one with python -m policy.token_cache)")
    try:
        with np.load(path, allow_pickle=False) as z:
            header = json.loads(str(z["__header__"]))
    except Exception as e:  # zip / key / JSON errors
        raise TokenCacheError(f"{path}: not a token cache: {type(e).__name__}: {e}") from None
    if header.get("format") != FORMAT or header.get("format_version") != FORMAT_VERSION:
        raise TokenCacheError(f"{path}: format {header.get('format')!r} v{header.get('format_version')}, "
                              f"expected {FORMAT!r} v{FORMAT_VERSION}")
    return header


def load_token_cache(path: str | Path, bundle) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """``(token arrays, header)`` of the cache at ``path``, refused unless ``bundle``'s tokenizers made it."""
    header = read_header(path)
    want = tokenizer_fingerprint(bundle)
    if header["fingerprint"] != want:
        raise TokenCacheError(f"{path}: made with other tokenizers (fingerprint {header['fingerprint'][:12]}), the "
                              f"checkpoint's are {want[:12]}; re-make it with python -m policy.token_cache "
                              f"--checkpoint <that checkpoint>")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [f for f in FIELDS if f not in z.files]
            if missing:
                raise TokenCacheError(f"{path}: missing arrays {missing}")
            data = {f: z[f] for f in FIELDS}
    except TokenCacheError:
        raise
    except Exception as e:
        raise TokenCacheError(f"{path}: unreadable: {type(e).__name__}: {e}") from None
    n = int(header["n_samples"])
    bad = {f: len(v) for f, v in data.items() if len(v) != n}
    if bad:
        raise TokenCacheError(f"{path}: header says {n} samples, arrays hold {bad}")
    return data, header


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(prog="python -m policy.token_cache", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, nargs="+", help="dataset directories written by scenarios.collect")
    ap.add_argument("--checkpoint", required=True,
                    help="the stage-1/2 checkpoint whose tokenizers make the tokens (the --init of the training run)")
    ap.add_argument("--out", required=True, help="cache file to write (.npz)")
    ap.add_argument("--cameras", nargs="+", default=None, metavar="NAME",
                    help="cache the views of these cameras of the data (default: the checkpoint's, else the data's)")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    from policy.bundle import PolicyBundle
    from policy.checkpoint import CheckpointError
    from policy.dataset import DatasetError, read_metas
    from policy.training.tokenize import check_data_matches, load_tokenized

    try:
        meta = read_metas(args.data)
        bundle = PolicyBundle.load(args.checkpoint, "cpu", require_model=True)
        cams = args.cameras or (list(bundle.camera_names) if set(bundle.camera_names) <= set(meta["camera_names"])
                                else list(meta["camera_names"]))
        check_data_matches(bundle, meta, args.checkpoint, cams)
        # as policy.train does for a checkpoint fine-tuned on other views: the data's views become the layout
        bundle.camera_names = cams
        bundle.frame_offsets_s = [float(x) for x in meta.get("frame_offsets_s", [0.0])]
        data = load_tokenized(bundle, args.data, not args.no_progress)
    except (DatasetError, CheckpointError) as exc:
        raise SystemExit(str(exc)) from None
    out = save_token_cache(args.out, data, meta, tokenizer_fingerprint(bundle), args.data)
    print(json.dumps({"cache": str(out), "n_samples": int(len(data["img"])), "size_mb": round(out.stat().st_size / 1e6, 2),
                      "fingerprint": tokenizer_fingerprint(bundle)[:12]}), file=sys.stdout)
    return out


if __name__ == "__main__":
    main()
