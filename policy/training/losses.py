"""The masked-token losses: cross-entropy over the target modality's id range on the masked positions only (for
actions optionally against a Gaussian over neighbouring bins), and the aux target's loss beside the chunk."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from policy.bundle import PolicyBundle
from policy.training.batches import build_task_batch, known_prefix_mask, mask_targets

#: the loss weight (a ``LossWeights`` field) of each task
TASK_WEIGHT = {"mm2a": "action", "t2i": "image", "mmu": "text"}


def soft_bin_cross_entropy(logits: torch.Tensor, target: torch.Tensor, sigma_bins: float) -> torch.Tensor:
    """Cross-entropy against a Gaussian over neighbouring bins (std ``sigma_bins``) centred on ``target``."""
    k = torch.arange(logits.shape[-1], device=logits.device, dtype=torch.float32)
    soft = torch.exp(-0.5 * ((k[None] - target[:, None].float()) / sigma_bins) ** 2)
    soft = soft / soft.sum(-1, keepdim=True)
    return -(soft * logits.float().log_softmax(-1)).sum(-1).mean()


def masked_query(bundle: PolicyBundle, clean: np.ndarray, lay, task: str, rng, full_prob: float,
                 known_prefix_max: int = 0, known_prefix_prob: float = 0.0, aux_known_prob: float = 0.0):
    """``(masked tokens, target mask (B, T), aux rows (B,))`` of the clean batch ``clean``: MaskGIT masking of the
    target (mm2a: with known prefixes when ``known_prefix_max > 0``) and the aux target masked in the rows
    ``aux rows`` (all of them unless ``aux_known_prob`` > 0: then the truth is given in that share)."""
    model = bundle.model
    masked, mask = mask_targets(clean, lay.target_idx, model.vocab.mask_id, rng, full_prob if task == "mm2a" else 0.0)
    if task == "mm2a" and known_prefix_max > 0:
        cfg = bundle.model_cfg
        mask, _ = known_prefix_mask(mask, cfg.horizon, cfg.action_dim, rng, known_prefix_max, known_prefix_prob)
        sub = clean[:, lay.target_idx].copy()
        sub[mask] = model.vocab.mask_id
        masked = clean.copy()
        masked[:, lay.target_idx] = sub
    aux_rows = np.ones(len(clean), dtype=bool)  # the rows whose aux target is masked and scored
    if len(lay.aux_idx):  # masked, as in the query of run time; aux_known_prob: the truth given (the second pass)
        if aux_known_prob > 0:
            aux_rows = rng.random(len(clean)) >= aux_known_prob
        sub = masked[:, lay.aux_idx]
        sub[aux_rows] = model.vocab.mask_id
        masked[:, lay.aux_idx] = sub
    return masked, mask, aux_rows


def task_loss(bundle: PolicyBundle, data, task: str, idx: np.ndarray, rng, full_prob: float, device,
              action_sigma_bins: float = 0.0, known_prefix_max: int = 0, known_prefix_prob: float = 0.0,
              with_aux: bool = False, aux_known_prob: float = 0.0):
    """The masked-token loss of ``task`` on samples ``idx``; with ``with_aux`` (mm2a) ``(loss, aux loss or None)``:
    the aux target (the ball's 3-D positions) is masked in every query, as at run time, and scored beside the chunk."""
    model = bundle.model
    clean, lay = build_task_batch(bundle, data, task, idx)
    masked, mask, aux_rows = masked_query(bundle, clean, lay, task, rng, full_prob, known_prefix_max, known_prefix_prob,
                                          aux_known_prob)
    lo, _ = model.vocab.range_of(lay.target_modality)
    inp = torch.as_tensor(masked, device=device)
    tgt = torch.as_tensor(clean[:, lay.target_idx] - lo, device=device)
    m = torch.as_tensor(mask, device=device)
    h = model.hidden(inp, lay)
    logits = model.logits(h[:, torch.as_tensor(lay.target_idx, device=device)], lay.target_modality)
    if task == "mm2a" and action_sigma_bins > 0:
        loss = soft_bin_cross_entropy(logits[m], tgt[m], action_sigma_bins)
    else:
        loss = F.cross_entropy(logits[m].float(), tgt[m])
    if not with_aux:
        return loss
    if task != "mm2a" or not len(lay.aux_idx):
        return loss, None
    if not aux_rows.any():
        return loss, None
    return loss, aux_loss(model, h, clean, lay, aux_rows, lo, action_sigma_bins, device)


def aux_loss(model, h: torch.Tensor, clean: np.ndarray, lay, aux_rows: np.ndarray, lo: int, action_sigma_bins: float,
             device) -> torch.Tensor:
    """The loss of the aux target (action bins) in the rows ``aux_rows`` from the hidden states ``h`` of the query."""
    aux_idx = torch.as_tensor(lay.aux_idx, device=device)
    rows = torch.as_tensor(np.flatnonzero(aux_rows), device=device)
    aux_logits = model.logits(h[rows][:, aux_idx], "action").reshape(-1, model.vocab.range_of("action")[1] - lo)
    aux_tgt = torch.as_tensor(clean[aux_rows][:, lay.aux_idx] - lo, device=device).reshape(-1)
    sigma = action_sigma_bins if action_sigma_bins > 0 else 0.0
    return soft_bin_cross_entropy(aux_logits, aux_tgt, sigma) if sigma else F.cross_entropy(aux_logits.float(), aux_tgt)
