"""Inference API for the control stack: ``MMActPolicy.load(path).predict_chunk(images, instruction, q_rad)``.

One ``<|mm2a|>`` call tokenizes the frames (VQ encoder), the instruction (BPE) and the joint
angles (uniform bins over the Panda limits), then fills the whole ``H x 7`` action chunk in ONE
forward pass (``action_steps=1``) or in ``k`` confidence re-masking passes. ``known_actions``
fixes some chunk tokens (real-time chunking / inpainting) and fills in the rest.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from policy.action_tokenizer import ActionTokenizer
from policy.bundle import PolicyBundle
from policy.decoding import (
    decode_autoregressive,
    decode_parallel,
    decode_parallel_logits,
    expected_bins,
    fill_aux,
    target_tokens,
)

REFINE_WINDOW_SIGMAS = 4.0  # default sub-bin refinement window, in std of the training label's Gaussian
DEFAULT_CHECKPOINT = Path(__file__).resolve().parent / "checkpoints" / "mmact_small.pt"


class MMActPolicy:
    """A trained unified-token policy (greedy, deterministic decoding)."""

    def __init__(self, bundle: PolicyBundle) -> None:
        if bundle.model is None:
            raise ValueError("MMActPolicy needs a bundle with model weights")
        self.bundle = bundle
        self.model = bundle.model.eval()

    @classmethod
    def load(cls, path: str | Path = DEFAULT_CHECKPOINT, device: str = "cpu") -> "MMActPolicy":
        """Load a checkpoint (raises ``policy.checkpoint.CheckpointError`` naming any problem)."""
        return cls(PolicyBundle.load(path, device))

    # ---- properties the control stack reads ------------------------------
    @property
    def action_tokenizer(self) -> ActionTokenizer:
        return self.bundle.action_tokenizer

    @property
    def chunk_dt_s(self) -> float:
        """Spacing of the chunk's waypoints in seconds."""
        return self.bundle.chunk_dt_s

    @property
    def horizon(self) -> int:
        return self.bundle.model_cfg.horizon

    @property
    def default_refine_bins(self) -> int:
        """The sub-bin refinement window that matches how this checkpoint was trained.

        ``policy.train`` fits the action bins to a Gaussian label of std ``action_label_sigma_bins``
        (16 by default), so the predicted distribution around the right bin is that wide and its local
        mean is a finer estimate than the argmax bin: the window is +-4 std (64 bins). A checkpoint
        trained on one-hot labels (sigma 0) or without a recorded train config gets 0 (bin centres).
        """
        tc = self.bundle.info.get("train_config") or {}
        sigma = float(tc.get("action_label_sigma_bins") or 0.0)
        return round(REFINE_WINDOW_SIGMAS * sigma) if np.isfinite(sigma) and sigma > 0 else 0

    @property
    def aux_first(self) -> bool:
        """Whether an mm2a query fills the aux target (the ball's 3-D positions) in a first pass and decodes the chunk
        given it: checkpoints trained with ``aux_known_prob > 0`` (they learned to read those tokens)."""
        tc = self.bundle.info.get("train_config") or {}
        return bool(self.bundle.model_cfg.aux_positions) and float(tc.get("aux_known_prob") or 0.0) > 0

    def decode_mm2a(self, toks: torch.Tensor, lay, action_steps: int = 1):
        """The mm2a call itself (what the benchmark times): ``(filled tokens, logits of the chunk)``."""
        if self.aux_first:
            toks = fill_aux(self.model, toks, lay)
        return decode_parallel_logits(self.model, toks, lay, action_steps)

    @property
    def device(self) -> torch.device:
        return self.bundle.device

    # ---- input handling ----------------------------------------------------
    def _views(self, images: np.ndarray) -> np.ndarray:
        img = np.asarray(images)
        if img.ndim == 3:
            img = img[None]
        if img.ndim != 4 or img.shape[-1] != 3 or img.dtype != np.uint8:
            raise ValueError(f"images must be uint8 (V, H, W, 3), got {img.shape} {img.dtype}")
        if not 1 <= img.shape[0] <= self.bundle.model_cfg.max_views:
            raise ValueError(f"got {img.shape[0]} views; this model takes 1..{self.bundle.model_cfg.max_views}")
        return img

    def _codes(self, images: np.ndarray) -> np.ndarray:
        return self.bundle.image_codes(self._views(images)[None])  # (1, V, g, g)

    def _text(self, text: str) -> np.ndarray:
        return self.bundle.text_batch([text], self.bundle.model_cfg.max_text_len)

    def mm2a_batch(self, images: np.ndarray, instruction: str, q_rad: np.ndarray,
                   known_actions: np.ndarray | None = None):
        """(tokens tensor (1, L), layout) of an mm2a query with the chunk masked (or partly known)."""
        q = np.asarray(q_rad, dtype=np.float64).reshape(-1)
        if q.shape != (self.bundle.model_cfg.state_dim,):
            raise ValueError(f"q_rad must have {self.bundle.model_cfg.state_dim} values, got shape {np.shape(q_rad)}")
        state = self.bundle.state_tokens(q[None])
        views = self._views(images)
        cfg, balls = self.bundle.model_cfg, None
        n_img = min(self.bundle.mm2a_image_views, len(views)) if self.bundle.mm2a_image_frames else len(views)
        if cfg.ball_views:  # the balls of every view, found in these very frames (policy.ball_detector)
            if len(views) != cfg.ball_views:
                raise ValueError(f"this model takes {cfg.ball_views} views (cameras x frames), got {len(views)}")
            balls = self.bundle.ball_tokens(views[None]).reshape(1, -1)
        codes = self.bundle.image_codes(views[None, :n_img])
        toks, lay = self.bundle.builder.fill("mm2a", self._text(instruction), codes, state, None, ball_tokens=balls)
        if known_actions is not None:
            h, d = self.horizon, self.bundle.model_cfg.action_dim
            known = np.asarray(known_actions)
            if known.shape != (h, d) or not np.issubdtype(known.dtype, np.integer):
                raise ValueError(f"known_actions must be int ({h}, {d}) with -1 = unknown, got {known.shape} {known.dtype}")
            lo, hi = self.model.vocab.range_of("action")
            bad = (known != -1) & ((known < lo) | (known >= hi))
            if bad.any():
                raise ValueError(f"known_actions holds token {int(known[bad][0])} outside the action range [{lo}, {hi})")
            flat = known.reshape(-1)
            tgt = toks[0, lay.target_idx]
            toks[0, lay.target_idx] = np.where(flat >= 0, flat, tgt)
        return torch.as_tensor(toks, device=self.device), lay

    # ---- the three tasks -----------------------------------------------------
    @torch.no_grad()
    def predict_chunk(self, images: np.ndarray, instruction: str, q_rad: np.ndarray, action_steps: int = 1,
                      known_actions: np.ndarray | None = None, refine_bins: int | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """mm2a: frames ``(V, H, W, 3)`` uint8 + instruction + joint angles (rad) -> action chunk.

        Returns ``(tokens (H, 7) int64 in the shared vocabulary, actions (H, 7) float64)``; the tokens
        are the greedy (argmax) ones whatever ``refine_bins`` is.
        ``action_steps=1`` fills the chunk in one forward pass; ``k > 1`` re-masks the least
        confident tokens on a cosine schedule. ``known_actions`` (H, 7) int64, -1 = unknown: the
        known tokens are kept and the rest inpainted. ``refine_bins=0`` returns bin centres of the
        greedy tokens; ``w > 0`` returns, for each predicted token, the probability-weighted mean
        bin within ``+-w`` bins of it (same forward pass, no extra cost beyond a softmax); None
        (default) = ``default_refine_bins``, the window matched to the checkpoint's training labels.
        Known tokens stay at their bin centres either way.
        """
        if refine_bins is None:
            refine_bins = self.default_refine_bins
        if refine_bins < 0:
            raise ValueError(f"refine_bins must be >= 0, got {refine_bins}")
        toks, lay = self.mm2a_batch(images, instruction, q_rad, known_actions)
        filled, logits = self.decode_mm2a(toks, lay, action_steps)
        out = target_tokens(filled, lay)[0]
        tokens = out.cpu().numpy().reshape(self.horizon, -1).astype(np.int64)
        if refine_bins == 0 or logits is None:
            return tokens, self.action_tokenizer.decode(tokens)
        lo, _ = self.model.vocab.range_of("action")
        bins = (tokens - lo).astype(np.float64)
        refined = expected_bins(logits[0], out - lo, refine_bins).cpu().numpy().reshape(bins.shape)
        known = np.asarray(known_actions) >= 0 if known_actions is not None else np.zeros(bins.shape, bool)
        return tokens, self.action_tokenizer.decode_fractional(np.where(known, bins, refined))

    @torch.no_grad()
    def predict_ball_positions(self, images: np.ndarray, instruction: str, q_rad: np.ndarray) -> np.ndarray:
        """The aux target of a model with ``aux_positions > 0``: where it says the instructed ball is (at t, then at
        the earlier frame), ``(P, 3)`` m, from the same query as ``predict_chunk`` (probability-weighted bins)."""
        if not self.bundle.model_cfg.aux_positions:
            raise ValueError("this checkpoint has no auxiliary ball-position target")
        toks, lay = self.mm2a_batch(images, instruction, q_rad)
        h = self.model.hidden(toks, lay)
        logits = self.model.logits(h[:, torch.as_tensor(lay.aux_idx, device=toks.device)], "action")[0]
        bins = expected_bins(logits[None], logits.argmax(-1)[None], max(self.default_refine_bins, 0))[0].cpu().numpy()
        return self.bundle.aux_positions_m(bins.reshape(-1, 3))

    @torch.no_grad()
    def predict_chunk_autoregressive(self, images: np.ndarray, instruction: str, q_rad: np.ndarray
                                     ) -> tuple[np.ndarray, np.ndarray]:
        """The same chunk decoded one token per forward pass, left to right (for comparison)."""
        toks, lay = self.mm2a_batch(images, instruction, q_rad)
        out = target_tokens(decode_autoregressive(self.model, toks, lay), lay)[0].cpu().numpy()
        tokens = out.reshape(self.horizon, -1).astype(np.int64)
        return tokens, self.action_tokenizer.decode(tokens)

    @torch.no_grad()
    def answer(self, images: np.ndarray, question: str, steps: int = 4) -> str:
        """mmu: frames + question -> answer text (iterative re-masking, cosine schedule)."""
        toks, lay = self.bundle.builder.fill("mmu", self._text(question), self._codes(images), None, None)
        out = target_tokens(decode_parallel(self.model, torch.as_tensor(toks, device=self.device), lay, steps), lay)
        ids = out[0].cpu().numpy() - self.model.vocab.text_offset
        return self.bundle.text_tokenizer.decode(ids).strip()

    @torch.no_grad()
    def predict_future_codes(self, images: np.ndarray, instruction: str, steps: int = 8) -> np.ndarray:
        """t2i: frames + instruction -> future image codes ``(V, grid, grid)`` int64, raw codebook indices.

        Decode them to pixels with ``policy.bundle.image_tokenizer.decode``.
        """
        codes = self._codes(images)
        toks, lay = self.bundle.builder.fill("t2i", self._text(instruction), codes, None, None)
        out = target_tokens(decode_parallel(self.model, torch.as_tensor(toks, device=self.device), lay, steps), lay)
        g = self.bundle.model_cfg.grid
        return (out[0].cpu().numpy() - self.model.vocab.image_offset).reshape(codes.shape[1], g, g).astype(np.int64)

    def decode_image_codes(self, codes: np.ndarray) -> np.ndarray:
        """Codes ``(V, grid, grid)`` -> uint8 frames ``(V, H, W, 3)``."""
        return self.bundle.image_tokenizer.decode(np.asarray(codes))
