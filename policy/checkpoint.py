"""One-file checkpoints: configs, weights, tokenizers, training record; checked on load.

The file is a ``torch.save`` dict::

    format, format_version, model_config, image_tokenizer_config, action_tokenizer, state_tokenizer,
    text_tokenizer_json, chunk_dt_s, camera_names, model_state (None after stage 0),
    image_tokenizer_state, weights_sha256, info

``weights_sha256`` hashes every tensor (name, dtype, shape, bytes), so a flipped bit is caught
even where ``torch.load`` would succeed. Saving is atomic (temp file + rename). Loading raises
``CheckpointError`` with the path and the problem: unreadable / truncated file, wrong format,
newer version, missing key, checksum mismatch, or weights that do not fit the stored config.
"""

from __future__ import annotations

import hashlib
import io
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

FORMAT = "mmact-ctrl/policy-checkpoint"
FORMAT_VERSION = 1
REQUIRED_KEYS = (
    "format", "format_version", "model_config", "image_tokenizer_config", "action_tokenizer", "state_tokenizer",
    "text_tokenizer_json", "chunk_dt_s", "model_state", "image_tokenizer_state", "weights_sha256",
)


class CheckpointError(RuntimeError):
    """A checkpoint file is unreadable, corrupt, or does not match what the code expects."""


def weights_digest(*state_dicts: dict[str, torch.Tensor] | None) -> str:
    h = hashlib.sha256()
    for i, sd in enumerate(state_dicts):
        h.update(f"#{i}".encode())
        if sd is None:
            h.update(b"none")
            continue
        for name in sorted(sd):
            t = sd[name].detach().cpu().contiguous()
            h.update(f"{name}|{t.dtype}|{tuple(t.shape)}".encode())
            h.update(t.view(-1).view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    return h.hexdigest()


def cpu_state(module: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().cpu().clone() for k, v in module.state_dict().items()}


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> Path:
    """Write ``payload`` (see module doc) atomically; fills ``format``, version and checksum."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = dict(payload)
    payload["format"] = FORMAT
    payload["format_version"] = FORMAT_VERSION
    payload["weights_sha256"] = weights_digest(payload.get("model_state"), payload.get("image_tokenizer_state"))
    missing = [k for k in REQUIRED_KEYS if k not in payload]
    if missing:
        raise CheckpointError(f"refusing to save {path}: payload lacks {missing}")
    buf = io.BytesIO()
    torch.save(payload, buf)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(buf.getvalue())
    os.replace(tmp, path)
    return path


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read and verify a checkpoint; raises ``CheckpointError`` naming the problem."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {path} does not exist")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:
        raise CheckpointError(
            f"checkpoint {path} is corrupt or truncated (torch.load failed: {type(e).__name__}: {str(e)[:200]})"
        ) from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        got = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise CheckpointError(f"{path} is not an mmact-ctrl policy checkpoint (format {got!r}, expected {FORMAT!r})")
    if payload.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(
            f"{path} has checkpoint format version {payload.get('format_version')!r}; this code reads version {FORMAT_VERSION}"
        )
    missing = [k for k in REQUIRED_KEYS if k not in payload]
    if missing:
        raise CheckpointError(f"{path} lacks required entries {missing}")
    digest = weights_digest(payload["model_state"], payload["image_tokenizer_state"])
    if digest != payload["weights_sha256"]:
        raise CheckpointError(f"{path}: weights checksum mismatch (stored {payload['weights_sha256'][:12]}..., "
                              f"computed {digest[:12]}...): the file is corrupt")
    return payload


def load_state_strict(module: torch.nn.Module, state: dict[str, torch.Tensor], what: str, path: str | Path) -> None:
    """``load_state_dict`` with a clear error for missing/unexpected keys or shape mismatches."""
    own = module.state_dict()
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    shapes = [f"{k}: checkpoint {tuple(state[k].shape)} vs model {tuple(own[k].shape)}"
              for k in sorted(set(own) & set(state)) if tuple(own[k].shape) != tuple(state[k].shape)]
    if missing or unexpected or shapes:
        parts = []
        if missing:
            parts.append(f"missing {missing[:5]}{'...' if len(missing) > 5 else ''}")
        if unexpected:
            parts.append(f"unexpected {unexpected[:5]}{'...' if len(unexpected) > 5 else ''}")
        if shapes:
            parts.append("shape mismatch " + "; ".join(shapes[:5]))
        raise CheckpointError(f"{path}: {what} weights do not match its config: " + ", ".join(parts))
    module.load_state_dict(state, strict=True)


def tokenizer_dict(tok) -> dict[str, Any]:
    """An ``ActionTokenizer`` as plain data."""
    return {"bins": int(tok.bins), "low": [float(x) for x in tok.bounds.low], "high": [float(x) for x in tok.bounds.high],
            "token_offset": int(tok.token_offset)}


def tokenizer_from_dict(d: dict[str, Any]):
    from policy.action_tokenizer import ActionBounds, ActionTokenizer

    return ActionTokenizer(bins=int(d["bins"]), bounds=ActionBounds(tuple(d["low"]), tuple(d["high"])),
                           token_offset=int(d["token_offset"]))


def to_numpy_safe(x: Any) -> Any:
    """JSON-friendly copy of small nested values (for model cards)."""
    if isinstance(x, dict):
        return {k: to_numpy_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [to_numpy_safe(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return x
