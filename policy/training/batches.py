"""One task's training query: the clean tokens of a batch, the MaskGIT masking of its target, known prefixes.

Training is masked-token prediction (MaskGIT / LLaDA): per sample a mask ratio ``cos(pi/2 * u)``, ``u ~ U(0, 1)``,
over the target segment; for mm2a a share ``full_prob`` of the samples has the whole chunk masked (the one-pass
case), and a share of them may get a known prefix (the inpainting query of real-time chunking).
"""

from __future__ import annotations

import numpy as np

from policy.bundle import PolicyBundle
from policy.dataset import DatasetError


def build_task_batch(bundle: PolicyBundle, data: dict[str, np.ndarray], task: str, idx: np.ndarray):
    """(clean tokens (B, L), layout) for samples ``idx`` of ``task``, the target filled with the truth.

    mm2a sees every view (cameras x frames); t2i and mmu the current frame of each camera."""
    b = bundle.builder
    img = data["img"][idx].astype(np.int64)
    if task != "mm2a":
        img = img[:, : bundle.n_cameras]
    if task == "mm2a":
        cfg = bundle.model_cfg
        balls = data["ball"][idx].astype(np.int64).reshape(len(idx), -1) if cfg.ball_views else None
        return b.fill("mm2a", data["instr"][idx], img[:, : bundle.mm2a_image_views], data["state"][idx],
                      data["action"][idx].reshape(len(idx), -1), ball_tokens=balls, aux_tokens=aux_truth(bundle, data, idx))
    if task == "t2i":
        fut = data["fut"][idx].astype(np.int64).reshape(len(idx), -1) + bundle.model.vocab.image_offset
        return b.fill("t2i", data["instr"][idx], img, None, fut)
    ans = data["answer"][idx] + bundle.model.vocab.text_offset
    return b.fill("mmu", data["quest"][idx], img, None, ans)


def aux_truth(bundle: PolicyBundle, data: dict[str, np.ndarray], idx: np.ndarray) -> np.ndarray | None:
    """Tokens ``(B, P*3)`` of the aux target of samples ``idx``: the instructed ball at t (and at the earlier frame);
    None for a model without one."""
    p = bundle.model_cfg.aux_positions
    if not p:
        return None
    pos = [data["target_pos_m"][idx], data["target_prev_pos_m"][idx]][:p]
    if p > 2:
        raise ValueError(f"aux_positions {p}: the data holds the ball at t and at the earlier frame only")
    pos = np.stack(pos, axis=1).astype(np.float64)  # (B, P, 3)
    if not np.all(np.isfinite(pos)):
        raise DatasetError("the aux target needs target_prev_pos_m in the data (collected since issue 25)")
    return bundle.aux_tokens(pos).reshape(len(idx), -1)


def mask_targets(tokens: np.ndarray, target_idx: np.ndarray, mask_id: int, rng: np.random.Generator,
                 full_prob: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """MaskGIT masking of the target positions: (masked tokens, bool mask (B, T))."""
    bsz, t = len(tokens), len(target_idx)
    ratio = np.cos(np.pi / 2 * rng.random(bsz))
    if full_prob > 0:
        ratio = np.where(rng.random(bsz) < full_prob, 1.0, ratio)
    n = np.clip(np.ceil(ratio * t), 1, t).astype(np.int64)
    rank = np.argsort(np.argsort(rng.random((bsz, t)), axis=1), axis=1)
    mask = rank < n[:, None]
    out = tokens.copy()
    sub = out[:, target_idx]
    sub[mask] = mask_id
    out[:, target_idx] = sub
    return out, mask


def known_prefix_mask(mask: np.ndarray, horizon: int, action_dim: int, rng: np.random.Generator, max_waypoints: int,
                      prob: float) -> tuple[np.ndarray, np.ndarray]:
    """Turn a share ``prob`` of the rows of an mm2a target mask ``(B, H*D)`` into inpainting queries: the first
    ``n ~ U{0..max_waypoints}`` waypoints known (unmasked, no loss), the rest of the chunk masked.

    Returns ``(mask, n_known (B,))``; rows not drawn keep their mask and ``n_known = 0``."""
    bsz = len(mask)
    n_known = np.zeros(bsz, dtype=np.int64)
    if max_waypoints <= 0 or prob <= 0:
        return mask, n_known
    rows = rng.random(bsz) < prob
    n_known[rows] = rng.integers(0, max_waypoints + 1, size=int(rows.sum()))
    pos = np.arange(horizon * action_dim)[None] // action_dim  # waypoint of each target position
    prefix_mask = pos >= n_known[:, None]
    return np.where(rows[:, None], prefix_mask, mask), n_known
