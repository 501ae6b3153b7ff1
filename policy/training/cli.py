"""Train the policy in three stages; each writes ``OUT/stage{N}.pt`` and ``OUT/MODEL_CARD.md``.

    stage 0: the tokenizers: byte-level BPE on the instruction/question/answer strings and the
             VQ-VAE image quantizer on the frames (images and future images) -> no model weights.
             With ``--init CKPT`` (new cameras or scenes for a trained policy): the checkpoint's text
             tokenizer and model are kept and its VQ-VAE is fine-tuned on the new frames, so the codes keep
             their meaning for the model (dead codes restart on the new content); stage 2 then continues it.
    stage 1: (``--init`` a stage-0 checkpoint) masked-token training of t2i + mmu, action loss off.
    stage 2: (``--init`` a stage-1 checkpoint) loss weights action 1.0, text 0.05, image 0.05.

Example (synthetic data)::

    python -m policy.synthetic /tmp/syn --n 4000
    python -m policy.train --data /tmp/syn --stage 0 --out runs/s0 --steps 1500
    python -m policy.train --data /tmp/syn --stage 1 --out runs/s1 --init runs/s0/stage0.pt --steps 2000
    python -m policy.train --data /tmp/syn --stage 2 --out runs/s2 --init runs/s1/stage1.pt --steps 5000

Training is masked-token prediction (MaskGIT / LLaDA): per sample a mask ratio
``cos(pi/2 * u)``, ``u ~ U(0, 1)``, over the target segment (for mm2a a share
``full_mask_prob_action`` of the samples has the whole chunk masked, the one-pass case),
cross-entropy over the target modality's id range on the masked positions only.
``--resume`` continues from ``OUT/resume_stage{N}.pt`` (written every ``--save-every`` steps).

Known prefixes (``--known-prefix-max W``, stage 2): a share ``--known-prefix-prob`` of the mm2a samples gets the
first ``n ~ U{0..W}`` waypoints of its chunk as known (unmasked) action tokens and the rest fully masked; the known
tokens are left out of the loss. That is the query ``--mode inpaint`` (real-time chunking) makes at run time
(DiscreteRTC, arXiv 2604.25050; training-time RTC, arXiv 2512.05964); one-pass decoding of an unconditioned
chunk stays the default query.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import torch

from policy.training.card import write_model_card
from policy.training.data import check_data_weights, resolve_data
from policy.training.stage0 import run_stage0
from policy.training.stage12 import run_stage12

PROG = "python -m policy.train"


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``python -m policy.train`` (the switches in the order ``--help`` lists them)."""
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    _data_args(ap)
    _run_args(ap)
    _optimiser_args(ap)
    _loss_args(ap)
    _layout_args(ap)
    _target_args(ap)
    _model_args(ap)
    _machine_args(ap)
    return ap


def _data_args(ap: argparse.ArgumentParser) -> None:
    """The data: dataset directories, token caches, the time budget, the directories' sampling weights."""
    ap.add_argument("--data", nargs="*", default=[],
                    help="dataset directory (meta.json + shard_XXXX.npz); several directories are trained on together "
                         "(they must agree on image size, cameras, chunk layout and action bins); may be left out "
                         "in stages 1/2 when --tokens-cache names an existing cache")
    ap.add_argument("--tokens-cache", nargs="+", default=None, metavar="FILE",
                    help="stages 1/2: the data's tokens in one file (policy.token_cache). Read when it exists (then "
                         "--data may be left out: the cache holds the dataset's meta), else written after tokenizing "
                         "--data. It lets an accelerator machine train without the frames. Several existing caches "
                         "of the same tokenizers train together (data that accumulates: one cache per collection); "
                         "--data-weights then takes one weight per directory of all of them, in order")
    ap.add_argument("--time-budget-s", type=float, default=None, metavar="S",
                    help="stages 1/2: wall-clock budget of the training loop (s; the evaluation after it is extra). "
                         "After 20 steps the speed is measured and --steps is lowered to what fits, so the learning-rate "
                         "schedule still runs to its end; the loop also stops if it runs past S")
    ap.add_argument("--data-weights", type=float, nargs="+", default=None, metavar="W",
                    help="stages 1/2: one sampling weight per --data directory: its samples are drawn W times as often "
                         "as a sample of weight 1 (default: every sample equally)")


def _run_args(ap: argparse.ArgumentParser) -> None:
    """The run: stage, output, start checkpoint, steps, seed, device, resume, bf16 autocast."""
    ap.add_argument("--stage", type=int, choices=(0, 1, 2), required=True)
    ap.add_argument("--out", required=True, help="output directory: stage{N}.pt, MODEL_CARD.md, resume_stage{N}.pt")
    ap.add_argument("--init", help="checkpoint to start from (stage 1: stage-0 tokenizers; stage 2: stage 1)")
    ap.add_argument("--steps", type=int, default=None, help="optimizer steps (default 1500 stage 0, 2000 stages 1/2)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    ap.add_argument("--resume", action="store_true", help="continue from OUT/resume_stage{N}.pt")
    ap.add_argument("--amp", action="store_true",
                    help="stages 1/2: bf16 autocast on the CPU too (always on with cuda); weights stay fp32. Measured "
                         "here: 1.25 s instead of 2.0 s per step on a 2-core CPU with avx512_bf16")


def _optimiser_args(ap: argparse.ArgumentParser) -> None:
    """Batches, learning rate, resume-file period, evaluation size."""
    ap.add_argument("--batch-size", type=int, default=None, help="per task (default 32)")
    ap.add_argument("--aux-batch-size", type=int, default=None,
                    help="stages 1/2: batch of the t2i and mmu tasks (default: --batch-size); small values make a "
                         "fine-tune that still rehearses them cheaper")
    ap.add_argument("--lr", type=float, default=None)
    ap.add_argument("--save-every", type=int, default=500)
    ap.add_argument("--eval-samples", type=int, default=256)


def _loss_args(ap: argparse.ArgumentParser) -> None:
    """The loss weights of the tasks and of the aux target, and the aux target's known share."""
    ap.add_argument("--w-action", type=float, default=None)
    ap.add_argument("--w-text", type=float, default=None)
    ap.add_argument("--w-image", type=float, default=None)
    ap.add_argument("--w-aux", type=float, default=None,
                    help="stage 2: weight of the aux target (the instructed ball's 3-D positions) of a model with "
                         "--aux-positions (default 0.5 when it has one)")
    ap.add_argument("--aux-known-prob", type=float, default=0.0,
                    help="stage 2: share of the mm2a samples whose aux target (the ball's true positions) is given, "
                         "so the chunk learns to read it; the checkpoint then decodes in two passes (positions, then "
                         "the chunk). Default 0: one pass, the aux target only shapes what the model computes")


def _layout_args(ap: argparse.ArgumentParser) -> None:
    """Stages 1/2: which cameras, ball tokens, aux target, image frames and text length a query holds."""
    ap.add_argument("--cameras", nargs="+", default=None, metavar="NAME",
                    help="stages 1/2: train on these cameras of the data (in this order; default: all of the data's)")
    ap.add_argument("--ball-tokens", type=int, choices=(0, 1), default=None,
                    help="stages 1/2 (not on --resume): 1 = every view's ball positions enter the mm2a query as tokens "
                         "(policy.ball_detector on the frames), 0 = none (default: the --init checkpoint's layout)")
    ap.add_argument("--aux-positions", type=int, choices=(0, 1, 2), default=None,
                    help="stages 1/2: predict the instructed ball's 3-D position at t (1) and at the earlier frame (2) "
                         "as an auxiliary mm2a target; 0 = none (default: the --init checkpoint's)")
    ap.add_argument("--mm2a-image-frames", type=int, default=None, metavar="K",
                    help="stages 1/2: the VQ codes of the first K frames enter the mm2a query (1 = the current frame; "
                         "the earlier one is then seen through its ball tokens only); 0 = all (default: --init's)")
    ap.add_argument("--max-text-len", type=int, default=None,
                    help="stages 1/2: text tokens of an instruction / question (default: --init's, 24)")


def _target_args(ap: argparse.ArgumentParser) -> None:
    """Soft action targets, known prefixes (inpainting) and regularisation."""
    ap.add_argument("--action-sigma-bins", type=float, default=16.0,
                    help="std (bins) of the Gaussian soft action targets (HL-Gauss); 0 = plain one-hot cross-entropy")
    ap.add_argument("--known-prefix-max", type=int, default=0, metavar="W",
                    help="stage 2: train for inpainting: a share --known-prefix-prob of the mm2a samples gets its first "
                         "U{0..W} waypoints as known tokens, left out of the loss (the published RTC query; W = H/2 = 8 "
                         "in the issue's recipe; default 0 = off)")
    ap.add_argument("--known-prefix-prob", type=float, default=0.5,
                    help="share of the mm2a samples that get a known prefix when --known-prefix-max > 0 (default 0.5)")
    ap.add_argument("--dropout", type=float, default=None,
                    help="dropout inside the transformer during this run (default: the model's own, 0). On the CPU with "
                         "two cameras x two frames (L = 734) dropout > 0 made a step ~5x slower here (14 s vs 2.7 s: "
                         "attention then runs on PyTorch's unfused math path)")
    ap.add_argument("--weight-decay", type=float, default=None, help="AdamW weight decay (default 0.01)")


def _model_args(ap: argparse.ArgumentParser) -> None:
    """The model's and the tokenizers' sizes (new ones only), the frame cap and the split seed."""
    ap.add_argument("--d-model", type=int, default=192)
    ap.add_argument("--layers", type=int, default=4)
    ap.add_argument("--heads", type=int, default=6)
    ap.add_argument("--strides", default=None,
                    help="stage 0: image encoder strides (default 2,2,2 -> 12x12 codes at 96 px; 2,2,3 -> 8x8). With "
                         "--init: other strides than the checkpoint's train a new VQ-VAE under its text tokenizer and "
                         "model (the image-code embeddings restart from the new codebook); the same or none fine-tune its own")
    ap.add_argument("--codebook-size", type=int, default=512)
    ap.add_argument("--text-vocab", type=int, default=512, help="stage 0: BPE vocabulary size (at most; the text range "
                    "of the shared vocabulary is the trained size)")
    ap.add_argument("--max-frames-per-shard", type=int, default=4000)
    ap.add_argument("--split-seed", type=int, default=1234)


def _machine_args(ap: argparse.ArgumentParser) -> None:
    """CPU threads and progress bars."""
    ap.add_argument("--threads", type=int, default=None,
                    help="torch CPU threads (on a shared, busy CPU 1 thread is often much faster than oversubscribing)")
    ap.add_argument("--no-progress", action="store_true")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The switches, checked (``ap.error``: exit status 2 and one line); sets ``--threads``."""
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.known_prefix_max < 0:
        ap.error(f"--known-prefix-max must be >= 0, got {args.known_prefix_max}")
    if not 0.0 <= args.known_prefix_prob <= 1.0:
        ap.error(f"--known-prefix-prob must be in [0, 1], got {args.known_prefix_prob}")
    if args.aux_batch_size is not None and args.aux_batch_size < 1:
        ap.error(f"--aux-batch-size must be >= 1, got {args.aux_batch_size}")
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.device == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda but no CUDA device is available")
    if args.time_budget_s is not None and not (math.isfinite(args.time_budget_s) and args.time_budget_s > 0):
        ap.error(f"--time-budget-s must be a finite number of seconds > 0, got {args.time_budget_s}")
    return args


def main(argv: list[str] | None = None) -> Path:
    """Run one stage; writes ``OUT/stage{N}.pt`` and ``OUT/MODEL_CARD.md``, prints the figures, returns the path."""
    args = parse_args(argv)
    meta = resolve_data(args)
    check_data_weights(args.data_weights, len(args.data))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ckpt = out / f"stage{args.stage}.pt"
    command = " ".join(shlex.quote(a) for a in [*PROG.split(), *sys.argv[1:]]) if argv is None else \
        " ".join([*PROG.split(), *argv])
    t0 = time.perf_counter()
    bundle, info, history = run_stage(args, meta, out, t0)
    info.update({"stage": args.stage, "command": command, "history": history, "data": " ".join(args.data), "seed": args.seed})
    collect_cfg = meta.get("collect_config") or {}
    if "plane_z_m" in collect_cfg:  # the scenes it was trained on (the evaluation builds the same ones)
        info["scene"] = {"plane_z_m": float(collect_cfg["plane_z_m"])}
    bundle.info = info
    bundle.save(ckpt, info)
    write_model_card(out / "MODEL_CARD.md", ckpt, args, meta, info, history)
    print(json.dumps({"checkpoint": str(ckpt), "figures": info.get("figures"), "final_losses": info.get("final_losses_ema")},
                     indent=1, default=float))
    return ckpt


def run_stage(args, meta: dict[str, Any], out: Path, t0: float) -> tuple[Any, dict[str, Any], list]:
    """``(bundle, info, history)`` of stage ``args.stage`` (started at ``time.perf_counter()`` = ``t0``);
    ``history``: the earlier stages of the checkpoint (a stage-0 refresh of a policy: that policy's, and itself)."""
    if args.stage == 0:
        args.steps = args.steps or 1500
        bundle, info = run_stage0(args, meta, args.device)
        info["wall_s"] = time.perf_counter() - t0
        history = list(info.pop("history", []))
        if info.get("init") and bundle.info.get("stage") is not None:  # the policy whose tokenizer was refreshed
            history.append({"stage": bundle.info.get("stage"), "command": bundle.info.get("command"),
                            "figures": bundle.info.get("figures", {})})
        return bundle, info, history
    bundle, info = run_stage12(args, meta, args.device, out)
    args.steps = info["train_config"]["steps"]
    history = list(bundle.info.get("history", []))
    prev = dict(bundle.info)
    if prev.get("stage") is not None:
        history.append({"stage": prev.get("stage"), "command": prev.get("command"), "figures": prev.get("figures", {})})
    info["text_size"] = bundle.model_cfg.text_size
    return bundle, info, history
