"""Training of the A2C2-style residual (``policy.residual``) from arrays: the episode split, the MLP's training loop
(AdamW, MSE in units of the bound, TCP-shift augmentation, cosine learning rate) and the offline errors.

The samples come from anywhere as a dict of arrays (``scenarios.train_residual`` collects them in open-loop
rollouts): ``features`` (n, FEATURE_DIM), ``label`` (n, 3) m, ``base`` (n, 3) m (the base waypoint),
``target`` (n, 3) m (the target at the sample time), ``target_lead`` (n, 3) m (at the label's lead), ``episode`` (n,)
(the index of the episode each sample came from) and optionally ``episodes`` (one dict per episode with its
``index`` and target ``kind``, for the errors by family).

This module imports only numpy, torch and tqdm (no MuJoCo, nothing of ``scenarios`` or ``mmact_ctrl``).
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
import torch
from tqdm import tqdm

from policy.residual import POS_SCALE_M, ResidualConfig, ResidualPolicy

#: the held-out split's loss is computed in slices of this many samples
VAL_SLICE = 65536


def clip_norm(v: np.ndarray, max_norm: float) -> np.ndarray:
    """``v`` (..., 3) scaled down to norm ``max_norm`` where longer."""
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v * np.minimum(1.0, max_norm / np.maximum(n, 1e-12))


def split_episodes(episode: np.ndarray, val_fraction: float, seed: int = 1234) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices (train, val), split by episode (a seeded share ``val_fraction`` of the episodes is held out)."""
    ids = np.unique(episode)
    rng = np.random.default_rng(seed)
    n_val = int(round(val_fraction * len(ids))) if len(ids) > 1 else 0
    n_val = min(max(n_val, 1 if val_fraction > 0 and len(ids) > 1 else 0), len(ids) - 1)
    val_ids = rng.permutation(ids)[:n_val]
    is_val = np.isin(episode, val_ids)
    return np.flatnonzero(~is_val), np.flatnonzero(is_val)


def _tcp_shift(x: torch.Tensor, y: torch.Tensor, prob: float, gen: torch.Generator) -> torch.Tensor:
    """Augmentation against the closed loop's state shift: a share ``prob`` of the samples sees the TCP moved
    toward where the corrected reference would have taken it (a random fraction of the label): the features
    ``meas - tcp`` shift by that much, so the network cannot read the label off the TCP's lag behind the target."""
    if prob <= 0:
        return x
    b = x.shape[0]
    u = torch.rand(b, 1, generator=gen) * (torch.rand(b, 1, generator=gen) < prob)
    x = x.clone()
    x[:, 3:6] -= u * y / POS_SCALE_M
    return x


def evaluate(policy: ResidualPolicy, data: dict, idx: np.ndarray) -> dict:
    """Errors (mm) of the corrected waypoint ``base + correction`` and of the base waypoint against the target (now
    and at the label's lead), and the best a bounded correction could do (the label itself)."""
    if len(idx) == 0:
        return {}
    corr = policy.correction_m(data["features"][idx].astype(np.float64))
    base = data["base"][idx].astype(np.float64)
    label = data["label"][idx].astype(np.float64)
    out = {"n": int(len(idx))}
    for name, tgt in (("now", data["target"][idx]), ("lead", data["target_lead"][idx])):
        tgt = tgt.astype(np.float64)
        out[f"base_err_{name}_mm"] = float(np.linalg.norm(base - tgt, axis=1).mean() * 1e3)
        out[f"corrected_err_{name}_mm"] = float(np.linalg.norm(base + corr - tgt, axis=1).mean() * 1e3)
        out[f"bounded_label_err_{name}_mm"] = float(np.linalg.norm(base + label - tgt, axis=1).mean() * 1e3)
    out["correction_vs_label_rmse_mm"] = float(np.sqrt(np.mean(np.sum((corr - label) ** 2, axis=1))) * 1e3)
    # where the bound does not bite, the error measures the network's precision alone
    tgt = data["target_lead"][idx].astype(np.float64)
    free = np.linalg.norm(tgt - base, axis=1) < policy.config.max_correction_m
    out["share_within_bound"] = float(free.mean())
    if free.any():
        out["base_err_within_bound_mm"] = float(np.linalg.norm(base - tgt, axis=1)[free].mean() * 1e3)
        out["corrected_err_within_bound_mm"] = float(np.linalg.norm(base + corr - tgt, axis=1)[free].mean() * 1e3)
    return out


def train(data: dict, config: ResidualConfig = ResidualConfig(), epochs: int = 30, batch_size: int = 512,
          lr: float = 2e-3, weight_decay: float = 1e-4, val_fraction: float = 0.15, seed: int = 0,
          tcp_shift_prob: float = 0.5, progress: bool = True, policy: ResidualPolicy | None = None
          ) -> tuple[ResidualPolicy, dict]:
    """Fit a :class:`ResidualPolicy` to ``data`` (the sample arrays of this module's docstring) with AdamW + MSE.

    The loss is the mean squared error of the correction in units of ``config.max_correction_m`` (so 1e-2 is
    an RMS error of 10 % of the bound). The learning rate decays with a cosine to 5 % over ``epochs``. The
    validation split holds out whole episodes. Returns the policy and ``info`` with the per-epoch history
    (``train_loss``: mean over the epoch's batches, ``val_loss``: over the whole held-out split), the final
    figures and the val / train errors of :func:`evaluate`.
    """
    if epochs < 1 or batch_size < 1 or not lr > 0:
        raise ValueError(f"train: epochs and batch_size must be >= 1 and lr > 0, got {epochs}, {batch_size}, {lr}")
    policy = policy or ResidualPolicy(config, seed=seed)
    net = policy.torch_module()
    tr, va = split_episodes(data["episode"], val_fraction)
    if len(tr) == 0:
        raise ValueError("train: no training samples")
    scale = 1.0 / policy.config.max_correction_m
    x_all = torch.as_tensor(data["features"], dtype=torch.float32)
    y_all = torch.as_tensor(data["label"], dtype=torch.float32) * scale
    x_tr, y_tr = x_all[tr], y_all[tr]
    gen = torch.Generator().manual_seed(int(seed))
    opt = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=weight_decay)
    total = epochs * max(1, math.ceil(len(tr) / batch_size))
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: 0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * min(s, total) / total)))
    history = []
    t0 = time.perf_counter()
    bar = tqdm(range(epochs), desc="training", unit="epoch", disable=not progress, file=sys.stderr)
    for epoch in bar:
        train_loss = _train_epoch(net, opt, sched, x_tr, y_tr, batch_size, scale, tcp_shift_prob, gen)
        history.append({"epoch": epoch, "train_loss": train_loss, "val_loss": _val_loss(net, x_all, y_all, va, scale)})
        bar.set_postfix(train=f"{history[-1]['train_loss']:.2e}", val=f"{history[-1]['val_loss']:.2e}")
    bar.close()
    net.eval()
    wall = time.perf_counter() - t0
    info = {
        "epochs": epochs, "steps": total, "batch_size": batch_size, "lr": lr, "weight_decay": weight_decay,
        "tcp_shift_prob": tcp_shift_prob, "seed": seed, "val_fraction": val_fraction,
        "n_samples": int(len(data["label"])), "n_train": int(len(tr)), "n_val": int(len(va)),
        "n_episodes_train": int(len(np.unique(data["episode"][tr]))),
        "n_episodes_val": int(len(np.unique(data["episode"][va]))) if len(va) else 0,
        "history": history, "final_train_loss": history[-1]["train_loss"], "final_val_loss": history[-1]["val_loss"],
        "train_wall_s": wall, "n_params": policy.n_params,
        "val": evaluate(policy, data, va), "train_eval": evaluate(policy, data, tr[:: max(1, len(tr) // 20000)]),
    }
    info["val_by_kind"] = by_kind(policy, data, va)
    return policy, info


def _train_epoch(net: torch.nn.Module, opt, sched, x_tr: torch.Tensor, y_tr: torch.Tensor, batch_size: int,
                 scale: float, tcp_shift_prob: float, gen: torch.Generator) -> float:
    """One pass over the training split in a random order (``gen``); returns the mean loss over its samples."""
    net.train()
    perm = torch.randperm(len(x_tr), generator=gen)
    run, count = 0.0, 0
    for i in range(0, len(x_tr), batch_size):
        b = perm[i:i + batch_size]
        x, y = _tcp_shift(x_tr[b], y_tr[b], tcp_shift_prob, gen), y_tr[b]
        loss = ((net(x) * scale - y) ** 2).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0)
        opt.step()
        sched.step()
        run += loss.item() * len(b)
        count += len(b)
    return run / count


def _val_loss(net: torch.nn.Module, x_all: torch.Tensor, y_all: torch.Tensor, va: np.ndarray, scale: float) -> float:
    """The loss over the held-out samples ``va`` (NaN when there are none)."""
    if len(va) == 0:
        return float("nan")
    net.eval()
    with torch.no_grad():
        loss = sum(float(((net(x_all[va[i:i + VAL_SLICE]]) * scale - y_all[va[i:i + VAL_SLICE]]) ** 2).mean(-1).sum())
                   for i in range(0, len(va), VAL_SLICE))
    return loss / len(va)


def by_kind(policy: ResidualPolicy, data: dict, idx: np.ndarray) -> dict:
    """:func:`evaluate` of the samples ``idx`` by target family (``data["episodes"]``' kinds; none: ``{}``)."""
    kinds = np.array([data["episodes"][e]["kind"] for e in range(len(data["episodes"]))]) if "episodes" in data else None
    if kinds is None or len(idx) == 0:
        return {}
    pos = {info["index"]: j for j, info in enumerate(data["episodes"])}
    sample_kind = np.array([kinds[pos[int(e)]] for e in data["episode"][idx]])
    return {k: evaluate(policy, data, idx[sample_kind == k]) for k in sorted(set(sample_kind))}
