"""Decoding of the target segment: parallel (one pass / k-step confidence re-masking) and autoregressive.

All decoders take a filled batch ``(B, L)`` whose target positions hold ``<|mask|>`` where unknown
and a given token where known (inpainting / real-time chunking). Known positions are never
changed. Logits are restricted to the id range of the layout's target modality, so the result
holds only tokens of that kind. Decoding is greedy (argmax), hence deterministic.

- ``decode_parallel(steps=1)``: every unknown position filled from ONE forward pass (mm2a default).
- ``decode_parallel(steps=k)``: MaskGIT-style: after pass ``s`` the ``ceil(n * cos(pi/2 * s/k))``
  least confident predictions are masked again (cosine schedule); t2i and mmu use this.
- ``expected_bins``: optional sub-bin refinement of an action token from its logits (the local
  probability-weighted mean around the chosen bin), for detokenizing to continuous values.
- ``decode_autoregressive``: one position per forward pass, left to right, for comparison.
- ``fill_aux``: the first pass of a checkpoint trained to read its own aux target (the ball's 3-D positions).
"""

from __future__ import annotations

import math

import torch

from policy.model import MMActModel
from policy.sequence import SeqLayout


def cosine_masked_count(n_unknown: int, step: int, steps: int) -> int:
    """Positions still masked after ``step`` (1-based) of ``steps``: ``floor(n * cos(pi/2 * step/steps))``."""
    if step >= steps:
        return 0
    return int(math.floor(n_unknown * math.cos(math.pi / 2 * step / steps)))


@torch.no_grad()
def decode_parallel(model: MMActModel, tokens: torch.Tensor, layout: SeqLayout, steps: int = 1) -> torch.Tensor:
    """Fill the masked target positions in ``steps`` passes; returns a new ``(B, L)`` tensor."""
    return decode_parallel_logits(model, tokens, layout, steps)[0]


@torch.no_grad()
def decode_parallel_logits(model: MMActModel, tokens: torch.Tensor, layout: SeqLayout,
                           steps: int = 1) -> tuple[torch.Tensor, torch.Tensor | None]:
    """``decode_parallel`` that also returns, per target position, the logits ``(B, T, range)`` of the
    pass that filled it (positions known from the start: the first pass's); None when nothing was
    masked, so no pass ran. With ``steps > 1`` a token committed in an early pass is an input of the
    later passes, so their logits at its position say nothing about it: hence per position."""
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    mask_id = model.vocab.mask_id
    lo, _ = model.vocab.range_of(layout.target_modality)
    idx = torch.as_tensor(layout.target_idx, device=tokens.device)
    out = tokens.clone()
    tgt = out[:, idx]
    unknown0 = tgt == mask_id  # (B, T)
    n0 = unknown0.sum(1)  # per sample
    fill_logits = None
    for s in range(1, steps + 1):
        unknown = out[:, idx] == mask_id
        if not bool(unknown.any()):
            break
        logits = model.target_logits(out, layout)
        fill_logits = logits if fill_logits is None else torch.where(unknown[..., None], logits, fill_logits)
        cur = out[:, idx]
        if s == steps:  # last (or only) pass: no confidences needed
            out[:, idx] = torch.where(unknown, logits.argmax(-1) + lo, cur)
            break
        prob, pred = logits.float().softmax(-1).max(-1)
        filled = torch.where(unknown, pred + lo, cur)
        if s < steps:
            keep_masked = torch.tensor([cosine_masked_count(int(n), s, steps) for n in n0], device=tokens.device)
            conf = torch.where(unknown, prob, torch.full_like(prob, float("inf")))
            order = conf.argsort(dim=1)  # least confident first
            rank = torch.empty_like(order)
            rank.scatter_(1, order, torch.arange(order.shape[1], device=tokens.device).expand_as(order))
            remask = unknown & (rank < keep_masked[:, None])
            filled = torch.where(remask, torch.full_like(filled, mask_id), filled)
        out[:, idx] = filled
    return out, fill_logits


@torch.no_grad()
def decode_autoregressive(model: MMActModel, tokens: torch.Tensor, layout: SeqLayout) -> torch.Tensor:
    """Fill the masked target positions one per forward pass, left to right."""
    mask_id = model.vocab.mask_id
    lo, _ = model.vocab.range_of(layout.target_modality)
    out = tokens.clone()
    for pos in layout.target_idx:
        col = out[:, pos]
        unknown = col == mask_id
        if not bool(unknown.any()):
            continue
        h = model.hidden(out, layout)[:, pos]
        pred = model.logits(h, layout.target_modality).argmax(-1) + lo
        out[:, pos] = torch.where(unknown, pred, col)
    return out


@torch.no_grad()
def expected_bins(logits: torch.Tensor, chosen: torch.Tensor, window: int) -> torch.Tensor:
    """Sub-bin refinement: the probability-weighted mean bin index within ``+-window`` bins of ``chosen``.

    ``logits`` ``(B, T, n_bins)`` restricted to the action range, ``chosen`` ``(B, T)`` bin indices
    (0-based, e.g. the argmax). The window keeps the mean local: a two-peaked distribution (two
    objects) is refined around the chosen peak, never averaged into the space between them.
    ``window=0`` returns ``chosen`` unchanged. Returns float bin indices ``(B, T)``.
    """
    if window < 0:
        raise ValueError(f"window must be >= 0 bins, got {window}")
    if window == 0:
        return chosen.to(torch.float64)
    n = logits.shape[-1]
    prob = logits.float().softmax(-1)
    bins = torch.arange(n, device=logits.device, dtype=torch.float32)
    near = (bins - chosen[..., None].float()).abs() <= window
    w = prob * near
    return ((w * bins).sum(-1) / w.sum(-1).clamp_min(1e-30)).to(torch.float64)


@torch.no_grad()
def fill_aux(model: MMActModel, tokens: torch.Tensor, layout: SeqLayout) -> torch.Tensor:
    """The first pass of a two-pass mm2a query: the aux target (the ball's 3-D positions) filled with its greedy
    tokens from one forward pass; the chunk is then decoded given them. A layout without an aux target: unchanged."""
    if not len(layout.aux_idx):
        return tokens
    idx = torch.as_tensor(layout.aux_idx, device=tokens.device)
    lo, _ = model.vocab.range_of("action")
    out = tokens.clone()
    h = model.hidden(out, layout)
    out[:, idx] = model.logits(h[:, idx], "action").argmax(-1) + lo
    return out


def target_tokens(tokens: torch.Tensor, layout: SeqLayout) -> torch.Tensor:
    """The target segment ``(B, T)`` of a decoded batch."""
    return tokens[:, torch.as_tensor(layout.target_idx, device=tokens.device)]
