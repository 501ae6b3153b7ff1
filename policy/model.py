"""The unified-token backbone: one embedding table, a bidirectional transformer, one (tied) output head.

Input: a ``(B, L)`` batch of shared-vocabulary ids in one of the fixed layouts of
``policy.sequence``. Each token's embedding is ``tok[id] + pos_a[type, a] + pos_b[type, b] +
view[v]`` (2D row/column embeddings for image codes, step/dimension for actions). The output
head is the embedding table transposed plus a bias, evaluated only over the id range of the
modality being predicted, so a prediction is always a token of the right kind.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from policy.config import ModelConfig
from policy.sequence import MAX_POS, N_TYPES, SeqLayout
from policy.vocab import VocabLayout


def vocab_of(cfg: ModelConfig) -> VocabLayout:
    return VocabLayout(text_size=cfg.text_size, image_codebook_size=cfg.image_codebook_size, action_bins=cfg.action_bins)


class MMActModel(nn.Module):
    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.vocab = vocab_of(cfg)
        d = cfg.d_model
        self.tok = nn.Embedding(self.vocab.size, d)
        self.pos_a = nn.Embedding(N_TYPES * MAX_POS, d)
        self.pos_b = nn.Embedding(N_TYPES * MAX_POS, d)
        self.view = nn.Embedding(cfg.max_views + 1, d)
        layer = nn.TransformerEncoderLayer(
            d, cfg.n_heads, cfg.ff_mult * d, cfg.dropout, activation="gelu", batch_first=True, norm_first=True
        )
        self.encoder = nn.TransformerEncoder(layer, cfg.n_layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(d)
        self.head_bias = nn.Parameter(torch.zeros(self.vocab.size))
        for emb in (self.tok, self.pos_a, self.pos_b, self.view):
            nn.init.normal_(emb.weight, std=0.02)

    def n_params(self) -> int:
        return sum(p.numel() for p in self.parameters())

    def hidden(self, tokens: torch.Tensor, layout: SeqLayout) -> torch.Tensor:
        """Ids ``(B, L)`` -> final hidden states ``(B, L, d)``."""
        if tokens.shape[1] != layout.length:
            raise ValueError(f"sequence length {tokens.shape[1]} does not match the {layout.task} layout ({layout.length})")
        pa, pb, vw = layout.position_tensors(tokens.device)
        x = self.tok(tokens) + (self.pos_a(pa) + self.pos_b(pb) + self.view(vw))[None]
        return self.norm(self.encoder(x))

    def logits(self, h: torch.Tensor, modality: str) -> torch.Tensor:
        """Hidden ``(..., d)`` -> logits over the id range of ``modality`` only (index 0 = range start)."""
        lo, hi = self.vocab.range_of(modality)
        return F.linear(h, self.tok.weight[lo:hi], self.head_bias[lo:hi])

    def target_logits(self, tokens: torch.Tensor, layout: SeqLayout) -> torch.Tensor:
        """Logits ``(B, T, range)`` at the target positions of ``layout``, restricted to its modality."""
        h = self.hidden(tokens, layout)
        idx = torch.as_tensor(layout.target_idx, device=tokens.device)
        return self.logits(h[:, idx], layout.target_modality)

    @torch.no_grad()
    def init_image_embeddings(self, codebook: torch.Tensor, seed: int = 0) -> None:
        """Start the image rows of the embedding table as a fixed random projection of the VQ codebook.

        Codes that are close in the quantizer's space then start close in the model's space,
        which helps rare codes (e.g. a ball at an unusual sub-patch offset).
        """
        g = torch.Generator().manual_seed(seed)
        k, dc = codebook.shape
        proj = torch.randn(dc, self.cfg.d_model, generator=g) / dc**0.5
        e = (codebook.float().cpu() - codebook.float().cpu().mean(0)) @ proj
        e = e / (e.std() + 1e-8) * 0.02
        lo, hi = self.vocab.range_of("image")
        if hi - lo != k:
            raise ValueError(f"codebook has {k} codes but the vocabulary's image range holds {hi - lo}")
        self.tok.weight[lo:hi] = e.to(self.tok.weight.device)

    @torch.no_grad()
    def init_action_embeddings(self, n_freqs: int | None = None) -> None:
        """Start the action-bin rows as sinusoidal features of the bin index (nearby bins start similar).

        The head is tied to the table, so the output over bins starts as a smooth function of the
        hidden state: the model can move its prediction along the bin axis instead of learning
        2048 unrelated classes (the ordinal structure that plain cross-entropy ignores).
        """
        lo, hi = self.vocab.range_of("action")
        bins, d = hi - lo, self.cfg.d_model
        n = n_freqs or d // 2
        u = (torch.arange(bins, dtype=torch.float64) + 0.5) / bins
        freqs = torch.logspace(0, math.log10(bins / 4), n, dtype=torch.float64)
        feats = torch.cat([torch.sin(2 * math.pi * u[:, None] * freqs), torch.cos(2 * math.pi * u[:, None] * freqs)], 1)
        feats = feats[:, :d]
        if feats.shape[1] < d:
            feats = torch.cat([feats, torch.zeros(bins, d - feats.shape[1], dtype=torch.float64)], 1)
        feats = feats / feats.std() * 0.02
        self.tok.weight[lo:hi] = feats.to(self.tok.weight)
