"""Stages 1/2: masked-token training of the model (stage 1: t2i + mmu, action loss off; stage 2: action 1.0, text and
image 0.05), optionally within a wall-clock budget, resumable, then the held-out evaluation."""

from __future__ import annotations

import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from policy.bundle import PolicyBundle
from policy.config import TrainConfig
from policy.dataset import split_indices
from policy.training.data import eval_subset, sampling_probabilities, training_tokens
from policy.training.evaluation import evaluate
from policy.training.losses import TASK_WEIGHT, task_loss
from policy.training.stage12_setup import load_or_init
from policy.training.tokenize import check_data_matches


@dataclass
class TrainingRun:
    """The state of one stage-1/2 run that the loop changes (and a resume file keeps)."""

    bundle: PolicyBundle
    tc: TrainConfig
    opt: torch.optim.Optimizer
    rng: np.random.Generator
    data: dict[str, np.ndarray]
    train_idx: np.ndarray
    draw_p: np.ndarray | None
    tasks: list[str]
    device: str
    resume_path: Path
    use_amp: bool = False
    start: int = 0
    log: list = field(default_factory=list)
    ema: dict[str, float] = field(default_factory=dict)
    wall0_s: float = 0.0
    t0: float = 0.0

    def wall_s(self) -> float:
        """Training wall time (s), the runs before a resume included."""
        return self.wall0_s + time.perf_counter() - self.t0

    def save_resume(self, step: int) -> None:
        torch.save({"bundle": self.bundle.payload(), "optimizer": self.opt.state_dict(), "step": step, "log": self.log,
                    "np_rng": self.rng.bit_generator.state, "torch_rng": torch.get_rng_state(),
                    "train_config": asdict(self.tc), "wall_s": self.wall_s()}, self.resume_path)


def run_stage12(args, meta: dict[str, Any], device: str, out: Path):
    """Train stage ``args.stage`` from ``--init`` (or ``--resume``); returns the bundle on the CPU and the run's info
    (held-out figures, final EMA losses, train config, wall time)."""
    resume_path = out / f"resume_stage{args.stage}.pt"
    bundle, tc, resume = load_or_init(args, meta, resume_path)
    check_data_matches(bundle, meta, args.init or resume_path, list(bundle.camera_names))
    if tc.known_prefix_max_waypoints >= bundle.model_cfg.horizon:
        raise SystemExit(f"--known-prefix-max {tc.known_prefix_max_waypoints} must be below the chunk horizon "
                         f"{bundle.model_cfg.horizon} (the issue's recipe: H/2)")
    run, val_idx = start_run(args, bundle, tc, resume, device, resume_path)
    train_loop(run, args)
    wall = run.wall_s()
    run.save_resume(run.tc.steps)
    return finish_run(run, val_idx, wall)


def start_run(args, bundle: PolicyBundle, tc: TrainConfig, resume: dict | None, device: str,
              resume_path: Path) -> tuple[TrainingRun, np.ndarray]:
    """Seed, read the data, split it, make the optimiser (a resume restores it, the step, the log and both RNGs);
    returns the run and the held-out indices."""
    torch.manual_seed(tc.seed)
    rng = np.random.default_rng(tc.seed)
    bundle.to(device)
    model = bundle.model
    if args.dropout is not None:  # regularisation for this run only: inference runs in eval mode either way
        for module in model.modules():
            if isinstance(module, torch.nn.Dropout):
                module.p = float(args.dropout)
    data = training_tokens(bundle, args)
    train_idx, val_idx = split_indices(len(data["img"]), tc.val_fraction, tc.split_seed)
    if len(train_idx) == 0:
        raise SystemExit("dataset too small: no training samples")
    draw_p = sampling_probabilities(data["source"][train_idx], args.data_weights, len(args.data))
    opt = torch.optim.AdamW(model.parameters(), lr=tc.lr, weight_decay=tc.weight_decay, betas=(0.9, 0.98))
    run = TrainingRun(bundle, tc, opt, rng, data, train_idx, draw_p, [], device, resume_path)
    if resume is not None:
        opt.load_state_dict(resume["optimizer"])
        run.start, run.log, run.wall0_s = int(resume["step"]), list(resume["log"]), float(resume["wall_s"])
        rng.bit_generator.state = resume["np_rng"]
        torch.set_rng_state(resume["torch_rng"])
    run.tasks = [t for t in ("mm2a", "t2i", "mmu") if getattr(tc.weights, TASK_WEIGHT[t]) > 0]
    if not run.tasks:
        raise SystemExit("all loss weights are 0")
    run.use_amp = device.startswith("cuda") or args.amp
    run.t0 = time.perf_counter()
    return run, val_idx


def train_loop(run: TrainingRun, args) -> None:
    """The optimiser steps from ``run.start`` to ``run.tc.steps`` (fewer within ``--time-budget-s``), a resume file
    every ``--save-every`` steps."""
    from tqdm import tqdm

    run.bundle.model.train()
    budget = StepBudget(getattr(args, "time_budget_s", None), run.start, run.t0)
    bar = tqdm(range(run.start, run.tc.steps), desc=f"stage {run.tc.stage}", initial=run.start, total=run.tc.steps,
               disable=args.no_progress)
    for step in bar:
        if budget.stops(step, run, bar):
            break
        losses = train_step(run, step)
        for k, v in losses.items():
            run.ema[k] = v if k not in run.ema else 0.98 * run.ema[k] + 0.02 * v
        if step % 10 == 0 or step == run.tc.steps - 1:
            bar.set_postfix({f"{k}": f"{v:.3f}" for k, v in run.ema.items()})
            run.log.append({"step": step, **{f"loss_{k}": round(v, 5) for k, v in losses.items()}})
        if args.save_every and (step + 1) % args.save_every == 0 and step + 1 < run.tc.steps:
            run.save_resume(step + 1)


def train_step(run: TrainingRun, step: int) -> dict[str, float]:
    """One optimiser step over every task's batch (weighted losses summed); returns each task's loss (and aux)."""
    tc, device = run.tc, run.device
    for g in run.opt.param_groups:
        g["lr"] = lr_at(step, tc)
    losses = {}
    total = torch.zeros((), device=device)
    amp_device = "cuda" if device.startswith("cuda") else "cpu"
    for task in run.tasks:
        bs = tc.batch_size if task == "mm2a" or not tc.aux_batch_size else tc.aux_batch_size
        if run.draw_p is None:
            idx = run.rng.choice(run.train_idx, size=bs, replace=len(run.train_idx) < bs)
        else:
            idx = run.rng.choice(run.train_idx, size=bs, replace=True, p=run.draw_p)
        with torch.autocast(amp_device, dtype=torch.bfloat16, enabled=run.use_amp):
            loss, aux = task_loss(run.bundle, run.data, task, idx, run.rng, tc.full_mask_prob_action, device,
                                  tc.action_label_sigma_bins, tc.known_prefix_max_waypoints, tc.known_prefix_prob,
                                  with_aux=True, aux_known_prob=tc.aux_known_prob)
        total = total + getattr(tc.weights, TASK_WEIGHT[task]) * loss
        losses[task] = float(loss.detach())
        if aux is not None and tc.weights.aux > 0:
            total = total + tc.weights.aux * aux
            losses["aux"] = float(aux.detach())
    run.opt.zero_grad(set_to_none=True)
    total.backward()
    torch.nn.utils.clip_grad_norm_(run.bundle.model.parameters(), tc.grad_clip)
    run.opt.step()
    return losses


def finish_run(run: TrainingRun, val_idx: np.ndarray, wall_s: float) -> tuple[PolicyBundle, dict[str, Any]]:
    """The held-out evaluation and the run's info; the bundle back on the CPU."""
    tc, bundle = run.tc, run.bundle
    bundle.model.eval()
    ev_idx = eval_subset(val_idx, tc.eval_samples, tc.split_seed)
    te = time.perf_counter()
    figures = evaluate(bundle, run.data, ev_idx, aux_first=bool(bundle.model_cfg.aux_positions) and tc.aux_known_prob > 0)
    figures["eval_wall_s"] = time.perf_counter() - te
    info = {"figures": figures, "n_samples": len(run.data["img"]), "n_train": int(len(run.train_idx)),
            "n_heldout": int(len(val_idx)), "final_losses_ema": {k: round(v, 4) for k, v in run.ema.items()},
            "train_config": asdict(tc), "train_wall_s": wall_s, "n_params": bundle.model.n_params(),
            "log_tail": run.log[-5:]}
    return bundle.to("cpu"), info


class StepBudget:
    """``--time-budget-s``: after ``WARM_STEPS`` untimed steps (allocations, kernel choice) the speed of the next
    ``CALIB_STEPS`` lowers the run's step count to what fits (so the learning-rate schedule still runs to its end);
    the loop also stops once the budget is spent."""

    WARM_STEPS = 10
    CALIB_STEPS = 20

    def __init__(self, budget_s: float | None, start: int, t0: float) -> None:
        self.budget_s, self.start, self.t0 = budget_s, start, t0
        self.t_warm: float | None = None

    def stops(self, step: int, run: TrainingRun, bar) -> bool:
        """Whether the loop stops before ``step`` (lowering ``run.tc.steps`` and the bar's total as it goes)."""
        if self.budget_s is None:
            return False
        budget = self.budget_s
        used = time.perf_counter() - self.t0
        if step == self.start + self.WARM_STEPS:
            self.t_warm = used
        if step == self.start + self.WARM_STEPS + self.CALIB_STEPS:
            rate_s = (used - self.t_warm) / self.CALIB_STEPS
            fit = budget_steps(step, 1, rate_s, budget - used, run.tc.steps)
            if fit < run.tc.steps:
                print(f"--time-budget-s {budget:g}: {rate_s:.3f} s/step, --steps {run.tc.steps} -> {fit}", file=sys.stderr)
                run.tc = replace(run.tc, steps=fit)
                bar.total = fit
        if step >= run.tc.steps or used > budget:
            if step < run.tc.steps:
                print(f"--time-budget-s {budget:g}: stopped after {step} steps ({used:.0f} s)", file=sys.stderr)
                run.tc = replace(run.tc, steps=step)
            return True
        return False


def lr_at(step: int, tc: TrainConfig) -> float:
    """Linear warm-up over ``tc.warmup_steps``, then a cosine from ``tc.lr`` down to 10 % of it at ``tc.steps``."""
    if step < tc.warmup_steps:
        return tc.lr * (step + 1) / tc.warmup_steps
    p = (step - tc.warmup_steps) / max(1, tc.steps - tc.warmup_steps)
    return tc.lr * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * min(1.0, p))))


def budget_steps(step: int, done: int, elapsed_s: float, left_s: float, planned: int) -> int:
    """The step count that fits the ``left_s`` seconds left, at step ``step``, at the speed of ``done`` steps
    measured in ``elapsed_s``. Never more than ``planned`` and never fewer than ``step`` (the steps made)."""
    if done <= 0 or elapsed_s <= 0:
        return planned
    fit = step + int(max(0.0, left_s) * done / elapsed_s)
    return int(max(step, min(planned, fit)))
