"""What a stage-1/2 run starts from: the bundle (``--init``'s, or a resume file's) with its layout switches, and the
``TrainConfig`` made from the switches."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

from policy.bundle import PolicyBundle
from policy.config import LossWeights, ModelConfig, TrainConfig


def load_or_init(args, meta: dict[str, Any], resume_path: Path) -> tuple[PolicyBundle, TrainConfig, dict | None]:
    """``(bundle, train config, resume payload or None)``: from ``resume_path`` with ``--resume`` (its config, with
    ``--steps`` when given), else from ``--init`` and the switches."""
    if args.resume:
        if not resume_path.is_file():
            raise SystemExit(f"--resume: no {resume_path} to resume from")
        resume = torch.load(resume_path, map_location="cpu", weights_only=False)
        bundle = PolicyBundle.from_payload(resume["bundle"], resume_path, "cpu")
        tc = TrainConfig(**{**resume["train_config"], "weights": LossWeights(**resume["train_config"]["weights"])})
        return bundle, replace(tc, steps=args.steps or tc.steps), resume
    if not args.init:
        raise SystemExit(f"stage {args.stage} needs --init: a stage-0 checkpoint (tokenizers) or a stage-1/2 checkpoint")
    bundle = init_bundle(args, meta)
    tc = train_config(args, bundle)
    adopt_data_views(bundle, args, meta)
    return bundle, tc, None


def init_bundle(args, meta: dict[str, Any]) -> PolicyBundle:
    """The ``--init`` checkpoint; a stage-0 one (tokenizers only) gets a new model of ``--d-model/--layers/--heads``
    (image-code embeddings from the codebook, action embeddings initialised); then the layout switches."""
    bundle = PolicyBundle.load(args.init, "cpu", require_model=False)
    if bundle.model is None:
        text_size = int(bundle.info.get("text_size", 512))
        mcfg = ModelConfig(text_size=text_size, image_codebook_size=bundle.image_cfg.codebook_size,
                           action_bins=bundle.action_tokenizer.bins, d_model=args.d_model, n_layers=args.layers,
                           n_heads=args.heads, grid=bundle.image_cfg.grid, horizon=int(meta["chunk_horizon"]),
                           dropout=args.dropout or 0.0)
        model = bundle.attach_model(mcfg)
        model.init_image_embeddings(bundle.image_tokenizer.codebook, seed=args.seed)
        model.init_action_embeddings()
    set_layout(bundle, args, meta)
    return bundle


def train_config(args, bundle: PolicyBundle) -> TrainConfig:
    """The ``TrainConfig`` of a run that does not resume: the stage's loss weights (each a switch), the optimiser's
    settings and the query shapes (known prefixes, the aux target's share given)."""
    w = LossWeights.for_stage(args.stage)
    aux_w = (0.5 if bundle.model_cfg.aux_positions and args.stage == 2 else 0.0) if args.w_aux is None else args.w_aux
    w = LossWeights(action=w.action if args.w_action is None else args.w_action,
                    text=w.text if args.w_text is None else args.w_text,
                    image=w.image if args.w_image is None else args.w_image, aux=aux_w)
    return TrainConfig(stage=args.stage, steps=args.steps or 2000, batch_size=args.batch_size or 32, lr=args.lr or 3e-4,
                       weight_decay=0.01 if args.weight_decay is None else args.weight_decay,
                       warmup_steps=min(200, max(1, (args.steps or 2000) // 10)), weights=w, seed=args.seed,
                       eval_samples=args.eval_samples, action_label_sigma_bins=args.action_sigma_bins,
                       aux_batch_size=args.aux_batch_size or 0, known_prefix_max_waypoints=args.known_prefix_max,
                       known_prefix_prob=args.known_prefix_prob, aux_known_prob=args.aux_known_prob)


def adopt_data_views(bundle: PolicyBundle, args, meta: dict[str, Any]) -> None:
    """A checkpoint trained on other views (e.g. one camera, one frame) fine-tuned on this data: its layout becomes
    the data's (``--cameras`` or all of the data's, x its frame offsets; the new views' embeddings start from their
    initial values)."""
    new_views = (list(args.cameras or meta["camera_names"]), [float(x) for x in meta.get("frame_offsets_s", [0.0])])
    if (list(bundle.camera_names), list(bundle.frame_offsets_s)) != new_views:
        print(f"views: {bundle.camera_names} x {bundle.frame_offsets_s} -> {new_views[0]} x {new_views[1]}",
              file=sys.stderr)
        bundle.camera_names, bundle.frame_offsets_s = new_views


def set_layout(bundle: PolicyBundle, args, meta: dict[str, Any]) -> None:
    """Issue 25's layout switches of a stage-1/2 run that does not resume: ball tokens, the aux target, fewer image
    frames in mm2a, a shorter text. The model's weights are unchanged (the new segments use the state type's
    position rows); the switches only change which tokens a query holds."""
    cfg = bundle.model_cfg
    n_frames = len(meta.get("frame_offsets_s", [0.0]))
    n_cams = len(args.cameras or meta["camera_names"])
    changes: dict[str, Any] = {}
    if args.ball_tokens is not None:
        changes["ball_views"] = n_cams * n_frames if args.ball_tokens else 0
        changes["ball_colors"] = len(bundle.ball_detector.colors)
    if args.aux_positions is not None:
        if args.aux_positions > min(2, n_frames):
            raise SystemExit(f"--aux-positions {args.aux_positions}: the data has the ball at t"
                             f"{' and at the earlier frame' if n_frames > 1 else ''} only")
        changes["aux_positions"] = args.aux_positions
    if args.max_text_len is not None:
        changes["max_text_len"] = args.max_text_len
    if changes:
        try:
            bundle.attach_model(replace(cfg, **changes), bundle.model)
        except ValueError as exc:
            raise SystemExit(f"layout: {exc}") from None
    if args.mm2a_image_frames is not None:
        if not 0 <= args.mm2a_image_frames <= n_frames:
            raise SystemExit(f"--mm2a-image-frames must be in [0, {n_frames}], got {args.mm2a_image_frames}")
        bundle.mm2a_image_frames = args.mm2a_image_frames
