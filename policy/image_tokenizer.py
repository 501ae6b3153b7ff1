"""Learned image quantizer: a small VQ-VAE with an EMA codebook.

A ``96 x 96`` RGB frame becomes a ``grid x grid`` map of codes in ``[0, codebook_size)``
(12 x 12 with 8 px patches by default) and decodes back. The codebook is updated by
exponential moving averages (no codebook gradient), dead codes are restarted from encoder
outputs, and the reconstruction loss up-weights pixels that differ from the frame's median
colour, so a 5-8 px coloured ball keeps its sub-patch position in its code.

Training lives in ``policy.train --stage 0`` (``train_image_tokenizer`` below does the steps).
"""

from __future__ import annotations

import math
import time

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from policy.config import ImageTokenizerConfig


class _ResBlock(nn.Module):
    def __init__(self, ch: int) -> None:
        super().__init__()
        self.c1 = nn.Conv2d(ch, ch, 3, padding=1)
        self.c2 = nn.Conv2d(ch, ch, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.c2(F.relu(self.c1(F.relu(x))))


class ImageTokenizer(nn.Module):
    """VQ-VAE. ``encode``: uint8 ``(N, H, W, 3)`` -> int64 codes ``(N, grid, grid)``; ``decode``: back to uint8."""

    def __init__(self, cfg: ImageTokenizerConfig) -> None:
        super().__init__()
        self.cfg = cfg
        enc: list[nn.Module] = []
        c_in = 3
        for s, c in zip(cfg.strides, cfg.channels):
            enc += [nn.Conv2d(c_in, c, s + 2, stride=s, padding=1), nn.ReLU()]
            c_in = c
        enc += [_ResBlock(c_in), nn.ReLU(), nn.Conv2d(c_in, cfg.code_dim, 1)]
        self.encoder = nn.Sequential(*enc)
        dec: list[nn.Module] = [nn.Conv2d(cfg.code_dim, c_in, 3, padding=1), _ResBlock(c_in)]
        chans = list(cfg.channels)
        for i in reversed(range(len(cfg.strides))):
            c_out = chans[i - 1] if i > 0 else 16
            dec += [nn.ReLU(), nn.ConvTranspose2d(chans[i], c_out, cfg.strides[i] + 2, stride=cfg.strides[i], padding=1)]
        dec += [nn.ReLU(), nn.Conv2d(16, 3, 3, padding=1)]
        self.decoder = nn.Sequential(*dec)
        k, d = cfg.codebook_size, cfg.code_dim
        self.register_buffer("codebook", torch.randn(k, d) * 0.1)
        self.register_buffer("ema_count", torch.ones(k))
        self.register_buffer("ema_sum", self.codebook.clone())
        self.register_buffer("initialized", torch.zeros((), dtype=torch.bool))

    # ---- pixels <-> floats --------------------------------------------
    def _to_float(self, images: np.ndarray | torch.Tensor) -> torch.Tensor:
        x = torch.as_tensor(np.asarray(images) if not isinstance(images, torch.Tensor) else images)
        if x.dtype != torch.uint8 or x.ndim != 4 or x.shape[-1] != 3:
            raise ValueError(f"images must be uint8 (N, H, W, 3), got {tuple(x.shape)} {x.dtype}")
        x = x.to(self.codebook.device).permute(0, 3, 1, 2).float() / 255.0
        s = self.cfg.image_size_px
        if x.shape[-2:] != (s, s):
            x = F.interpolate(x, size=(s, s), mode="area")
        return x * 2.0 - 1.0  # [-1, 1]

    # ---- quantization ---------------------------------------------------
    def _nearest(self, z: torch.Tensor, with_dist: bool = False):
        """z ``(N, D, g, g)`` -> code indices ``(N, g, g)`` (and the squared distance to the chosen code)."""
        flat = z.permute(0, 2, 3, 1).reshape(-1, z.shape[1])
        dist = flat.pow(2).sum(1, keepdim=True) - 2 * flat @ self.codebook.t() + self.codebook.pow(2).sum(1)[None]
        d, idx = dist.min(1)
        idx = idx.view(z.shape[0], z.shape[2], z.shape[3])
        return (idx, d.clamp_min(0)) if with_dist else idx

    def lookup(self, codes: torch.Tensor) -> torch.Tensor:
        """Codes ``(N, g, g)`` -> quantized vectors ``(N, D, g, g)``."""
        return self.codebook[codes].permute(0, 3, 1, 2)

    @torch.no_grad()
    def encode(self, images: np.ndarray | torch.Tensor) -> torch.Tensor:
        """uint8 ``(N, H, W, 3)`` -> int64 codes ``(N, grid, grid)`` in ``[0, codebook_size)``."""
        return self._nearest(self.encoder(self._to_float(images)))

    @torch.no_grad()
    def decode(self, codes: torch.Tensor | np.ndarray) -> np.ndarray:
        """Codes ``(N, grid, grid)`` -> uint8 images ``(N, H, W, 3)``."""
        c = torch.as_tensor(np.asarray(codes) if not isinstance(codes, torch.Tensor) else codes).long()
        c = c.to(self.codebook.device)
        if c.min() < 0 or c.max() >= self.cfg.codebook_size:
            raise ValueError(f"image codes must lie in [0, {self.cfg.codebook_size})")
        x = self.decoder(self.lookup(c))
        return ((x.clamp(-1, 1) + 1) * 127.5).round().byte().permute(0, 2, 3, 1).cpu().numpy()

    # ---- training --------------------------------------------------------
    def training_loss(self, images: np.ndarray | torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
        """One VQ-VAE training step's loss (also updates the EMA codebook when ``self.training``)."""
        x = self._to_float(images)
        z = self.encoder(x)
        flat = z.permute(0, 2, 3, 1).reshape(-1, z.shape[1])
        if self.training and not bool(self.initialized):
            with torch.no_grad():
                pick = torch.randint(0, flat.shape[0], (self.cfg.codebook_size,), device=flat.device)
                self.codebook.copy_(flat[pick].detach())
                self.ema_sum.copy_(self.codebook)
                self.ema_count.fill_(1.0)
                self.initialized.fill_(True)
        codes, qerr = self._nearest(z, with_dist=True)
        q = self.lookup(codes)
        if self.training:
            self._ema_update(flat.detach(), codes.view(-1), qerr.detach())
        commit = F.mse_loss(z, q.detach())
        zq = z + (q - z).detach()  # straight-through
        recon = self.decoder(zq)
        with torch.no_grad():
            med = x.flatten(2).median(dim=2).values[:, :, None, None]
            fg = ((x - med).abs().amax(1, keepdim=True) > 0.3).float()
            w = 1.0 + self.cfg.foreground_weight * fg
        err = (recon - x).pow(2)
        rec_loss = (err * w).mean()
        loss = rec_loss + self.cfg.commitment * commit
        mse01 = float(err.detach().mean()) / 4.0  # in [0, 1] pixel units
        usage = float(torch.unique(codes).numel()) / self.cfg.codebook_size
        return loss, {"recon": float(rec_loss.detach()), "commit": float(commit.detach()), "psnr_db": psnr_from_mse(mse01), "code_usage": usage}

    @torch.no_grad()
    def _ema_update(self, flat: torch.Tensor, idx: torch.Tensor, qerr: torch.Tensor) -> None:
        k, decay = self.cfg.codebook_size, self.cfg.ema_decay
        onehot = F.one_hot(idx, k).type_as(flat)
        self.ema_count.mul_(decay).add_(onehot.sum(0), alpha=1 - decay)
        self.ema_sum.mul_(decay).add_(onehot.t() @ flat, alpha=1 - decay)
        n = self.ema_count.sum()
        count = (self.ema_count + 1e-5) / (n + k * 1e-5) * n
        self.codebook.copy_(self.ema_sum / count[:, None])
        dead = self.ema_count < self.cfg.dead_code_threshold
        n_dead = int(dead.sum())
        if n_dead:  # restart from encoder outputs drawn in proportion to their quantization error
            pick = torch.multinomial(qerr + 1e-8, n_dead, replacement=n_dead > flat.shape[0])
            self.codebook[dead] = flat[pick]
            self.ema_sum[dead] = flat[pick]
            self.ema_count[dead] = 1.0


def psnr_from_mse(mse: float) -> float:
    """PSNR in dB of images in [0, 1] with mean squared error ``mse``."""
    return float(10.0 * math.log10(1.0 / max(mse, 1e-10)))


@torch.no_grad()
def evaluate_psnr(tok: ImageTokenizer, images: np.ndarray, batch: int = 64) -> float:
    """PSNR (dB) of encode -> decode over uint8 ``images`` (N, H, W, 3) at the tokenizer's resolution."""
    was = tok.training
    tok.eval()
    se, n = 0.0, 0
    for i in range(0, len(images), batch):
        chunk = images[i : i + batch]
        rec = tok.decode(tok.encode(chunk)).astype(np.float64) / 255.0
        ref = ((tok._to_float(chunk) + 1) / 2).permute(0, 2, 3, 1).cpu().numpy()
        se += float(((rec - ref) ** 2).sum())
        n += rec.size
    tok.train(was)
    return psnr_from_mse(se / max(n, 1))


def train_image_tokenizer(
    tok: ImageTokenizer,
    images: np.ndarray,
    steps: int,
    batch_size: int = 64,
    lr: float = 1e-3,
    seed: int = 0,
    device: str = "cpu",
    progress: bool = True,
    log: list | None = None,
) -> dict[str, float]:
    """Train ``tok`` on uint8 frames ``(N, H, W, 3)`` for ``steps`` steps; returns the last step's stats.

    Samples batches with a seeded generator; uses the cosine-decayed Adam learning rate.
    """
    from tqdm import tqdm

    tok.to(device).train()
    opt = torch.optim.Adam([p for p in tok.parameters()], lr=lr)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: 0.5 * (1 + math.cos(math.pi * min(s, steps) / max(steps, 1))))
    rng = np.random.default_rng(seed)
    stats: dict[str, float] = {}
    t0 = time.perf_counter()
    bar = tqdm(range(steps), desc="stage 0: image tokenizer", disable=not progress)
    for step in bar:
        idx = rng.integers(0, len(images), size=batch_size)
        loss, stats = tok.training_loss(images[np.sort(idx)])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        if step % 20 == 0 or step == steps - 1:
            bar.set_postfix(loss=f"{float(loss.detach()):.4f}", psnr=f"{stats['psnr_db']:.1f}", usage=f"{stats['code_usage']:.2f}")
            if log is not None:
                log.append({"step": step, "loss": float(loss.detach()), **stats})
    tok.eval()
    stats["wall_s"] = time.perf_counter() - t0
    return stats
