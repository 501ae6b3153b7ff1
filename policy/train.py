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
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from policy.action_tokenizer import ActionBounds, ActionTokenizer
from policy.bundle import PolicyBundle, make_state_tokenizer
from policy.checkpoint import CheckpointError
from policy.config import ImageTokenizerConfig, LossWeights, ModelConfig, TrainConfig
from policy.dataset import DatasetError, dataset_shards, read_metas, read_shard, split_indices
from policy.decoding import decode_parallel, fill_aux, target_tokens
from policy.image_tokenizer import ImageTokenizer, evaluate_psnr, train_image_tokenizer
from policy.text_tokenizer import TextTokenizer
from policy.token_cache import TokenCacheError, load_token_cache, read_header, save_token_cache, tokenizer_fingerprint
from policy.vocab import VocabLayout

TASK_WEIGHT = {"mm2a": "action", "t2i": "image", "mmu": "text"}
#: held-out frames whose expert chunk starts within this distance of the target count as "near the ball" (m).
NEAR_BALL_M = 0.06


# ---------------------------------------------------------------- data
def load_tokenized(bundle: PolicyBundle, data_path: str | list[str], progress: bool = True) -> dict[str, np.ndarray]:
    """Read every shard (of one or several dataset directories) and keep only tokens: codes of images /
    future images, text ids, state and action tokens; ``source`` is each sample's directory index."""
    from tqdm import tqdm

    read_metas(data_path)  # the directories must agree on the token layout
    cfg = bundle.model_cfg
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("img", "fut", "instr", "quest", "answer", "answer_str", "state",
                                                           "action", "actions_f", "target_pos_m", "source", "ball",
                                                           "target_prev_pos_m")}
    for k, shard, meta in tqdm(dataset_shards(data_path), desc="tokenizing shards", disable=not progress):
        views, future = check_views(bundle, meta, shard)
        d = read_shard(shard, meta)
        images = d["images"][:, views]
        parts["source"].append(np.full(len(d["q_rad"]), k, dtype=np.int16))
        parts["img"].append(bundle.image_codes(images).astype(np.int16))
        parts["fut"].append(bundle.image_codes(d["future_images"][:, future]).astype(np.int16))
        parts["ball"].append(bundle.ball_tokens(images).astype(np.int16))
        prev = d.get("target_prev_pos_m")
        parts["target_prev_pos_m"].append(np.full((len(d["q_rad"]), 3), np.nan, np.float32) if prev is None
                                          else prev.astype(np.float32))
        parts["instr"].append(bundle.text_batch(d["instructions"], cfg.max_text_len))
        parts["quest"].append(bundle.text_batch(d["questions"], cfg.max_text_len))
        parts["answer"].append(bundle.text_batch(d["answers"], cfg.max_answer_len, end_with_eot=True))
        parts["answer_str"].append(d["answers"])
        parts["state"].append(bundle.state_tokens(d["q_rad"]))
        parts["action"].append(bundle.action_tokens(d["actions"]))
        parts["actions_f"].append(d["actions"].astype(np.float32))
        parts["target_pos_m"].append(d["target_pos_m"].astype(np.float32))
    return {k: np.concatenate(v) for k, v in parts.items()}


def _caches(args) -> list[str]:
    cache = getattr(args, "tokens_cache", None)
    return [cache] if isinstance(cache, str) else list(cache or [])


def training_tokens(bundle: PolicyBundle, args) -> dict[str, np.ndarray]:
    """The token arrays of ``--data``, read from the ``--tokens-cache`` file(s) when they exist (and were made by this
    bundle's tokenizers; several are concatenated, each keeping its directories' ``source`` indices in the order of
    ``args.data``), else tokenized from the frames (and written to the one ``--tokens-cache`` when one is named)."""
    caches = _caches(args)
    if caches and all(Path(c).is_file() for c in caches):
        parts, n_dirs = [], 0
        for c in caches:
            try:
                data, header = load_token_cache(c, bundle)
            except TokenCacheError as exc:
                raise SystemExit(f"--tokens-cache: {exc}") from None
            data["source"] = (data["source"].astype(np.int64) + n_dirs).astype(np.int16)
            n_dirs += len(header["data_paths"])
            parts.append(data)
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if len(parts) > 1 else parts[0]
    data = load_tokenized(bundle, args.data, not args.no_progress)
    if caches:
        save_token_cache(caches[0], data, read_metas(args.data), tokenizer_fingerprint(bundle), list(args.data))
        print(f"tokens of {len(data['img'])} samples cached in {caches[0]}", file=sys.stderr)
    return data


def check_views(bundle: PolicyBundle, meta: dict[str, Any], where) -> tuple[list[int], list[int]]:
    """The data's frame offsets must be the bundle's and its cameras must include the bundle's (a dataset rendered
    with more cameras serves a policy of some of them). Returns the indices of the bundle's views among the data's
    ``images`` (frame-major) and among its ``future_images``."""
    offsets = [float(x) for x in meta.get("frame_offsets_s", [0.0])]
    cams = list(meta["camera_names"])
    if (not set(bundle.camera_names) <= set(cams) or len(offsets) != len(bundle.frame_offsets_s)
            or not np.allclose(offsets, bundle.frame_offsets_s)):
        raise DatasetError(f"{where}: cameras {meta['camera_names']} / frame offsets {offsets} differ from the "
                           f"checkpoint's {bundle.camera_names} / {bundle.frame_offsets_s}")
    future = [cams.index(c) for c in bundle.camera_names]
    return [f * len(cams) + c for f in range(len(offsets)) for c in future], future


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


def soft_bin_cross_entropy(logits: torch.Tensor, target: torch.Tensor, sigma_bins: float) -> torch.Tensor:
    """Cross-entropy against a Gaussian over neighbouring bins (std ``sigma_bins``) centred on ``target``."""
    k = torch.arange(logits.shape[-1], device=logits.device, dtype=torch.float32)
    soft = torch.exp(-0.5 * ((k[None] - target[:, None].float()) / sigma_bins) ** 2)
    soft = soft / soft.sum(-1, keepdim=True)
    return -(soft * logits.float().log_softmax(-1)).sum(-1).mean()


def task_loss(bundle: PolicyBundle, data, task: str, idx: np.ndarray, rng, full_prob: float, device,
              action_sigma_bins: float = 0.0, known_prefix_max: int = 0, known_prefix_prob: float = 0.0,
              with_aux: bool = False, aux_known_prob: float = 0.0):
    """The masked-token loss of ``task`` on samples ``idx``; with ``with_aux`` (mm2a) ``(loss, aux loss or None)``:
    the aux target (the ball's 3-D positions) is masked in every query, as at run time, and scored beside the chunk."""
    model = bundle.model
    clean, lay = build_task_batch(bundle, data, task, idx)
    masked, mask = mask_targets(clean, lay.target_idx, model.vocab.mask_id, rng, full_prob if task == "mm2a" else 0.0)
    if task == "mm2a" and known_prefix_max > 0:
        cfg = bundle.model_cfg
        mask, _ = known_prefix_mask(mask, cfg.horizon, cfg.action_dim, rng, known_prefix_max, known_prefix_prob)
        sub = clean[:, lay.target_idx].copy()
        sub[mask] = model.vocab.mask_id
        masked = clean.copy()
        masked[:, lay.target_idx] = sub
    aux_rows = np.ones(len(idx), dtype=bool)  # the rows whose aux target is masked and scored
    if len(lay.aux_idx):  # masked, as in the query of run time; aux_known_prob: the truth given (the second pass)
        if aux_known_prob > 0:
            aux_rows = rng.random(len(idx)) >= aux_known_prob
        sub = masked[:, lay.aux_idx]
        sub[aux_rows] = model.vocab.mask_id
        masked[:, lay.aux_idx] = sub
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
    aux_idx = torch.as_tensor(lay.aux_idx, device=device)
    rows = torch.as_tensor(np.flatnonzero(aux_rows), device=device)
    aux_logits = model.logits(h[rows][:, aux_idx], "action").reshape(-1, model.vocab.range_of("action")[1] - lo)
    aux_tgt = torch.as_tensor(clean[aux_rows][:, lay.aux_idx] - lo, device=device).reshape(-1)
    sigma = action_sigma_bins if action_sigma_bins > 0 else 0.0
    aux = soft_bin_cross_entropy(aux_logits, aux_tgt, sigma) if sigma else F.cross_entropy(aux_logits.float(), aux_tgt)
    return loss, aux


# ---------------------------------------------------------------- evaluation
@torch.no_grad()
def evaluate(bundle: PolicyBundle, data: dict[str, np.ndarray], idx: np.ndarray, tasks=("mm2a", "t2i", "mmu"),
             batch: int = 64, t2i_steps: int = 8, mmu_steps: int = 4, aux_first: bool = False) -> dict[str, float]:
    """Held-out figures: action token accuracy and error (m), t2i token accuracy, mmu answer accuracy; the aux
    target's errors (m). ``aux_first``: decode the chunk given the predicted aux target (two passes)."""
    model, dev = bundle.model, bundle.device
    model.eval()
    res: dict[str, float] = {"n_eval": int(len(idx))}
    acc = {k: [] for k in ("act_tok", "act_err", "act_final", "act_bin1", "t2i", "t2i_copy", "mmu", "aux_t", "aux_prev",
                           "aux_disp")}
    for s in range(0, len(idx), batch):
        j = idx[s : s + batch]
        if "mm2a" in tasks:
            clean, lay = build_task_batch(bundle, data, "mm2a", j)
            inp = clean.copy()
            inp[:, lay.target_idx] = model.vocab.mask_id
            if len(lay.aux_idx):
                inp[:, lay.aux_idx] = model.vocab.mask_id
                aux_lo = model.vocab.range_of("action")[0]
                h = model.hidden(torch.as_tensor(inp, device=dev), lay)
                aux_bins = model.logits(h[:, torch.as_tensor(lay.aux_idx, device=dev)], "action").argmax(-1).cpu().numpy()
                aux_pred = bundle.aux_positions_m(aux_bins.reshape(len(j), -1, 3))
                aux_true = np.stack([data["target_pos_m"][j], data["target_prev_pos_m"][j]], 1)[:, : aux_pred.shape[1]]
                err = np.linalg.norm(aux_pred - aux_true, axis=-1)
                acc["aux_t"].append(err[:, 0])
                if err.shape[1] > 1:
                    acc["aux_prev"].append(err[:, 1])
                    dv = (aux_pred[:, 0] - aux_pred[:, 1]) - (aux_true[:, 0] - aux_true[:, 1])
                    acc["aux_disp"].append(np.linalg.norm(dv, axis=-1))
            query = torch.as_tensor(inp, device=dev)
            if aux_first:
                query = fill_aux(model, query, lay)
            out = target_tokens(decode_parallel(model, query, lay, 1), lay).cpu().numpy()
            truth = clean[:, lay.target_idx]
            acc["act_tok"].append((out == truth).ravel())
            acc["act_bin1"].append((np.abs(out - truth) <= 1).ravel())
            pred = bundle.action_tokenizer.decode(out.reshape(len(j), -1, 7))
            err = np.linalg.norm(pred[..., :3] - data["actions_f"][j][..., :3], axis=-1)
            acc["act_err"].append(err.ravel())
            acc["act_final"].append(np.linalg.norm(pred[:, -1, :3] - data["target_pos_m"][j], axis=-1))
        if "t2i" in tasks:
            clean, lay = build_task_batch(bundle, data, "t2i", j)
            inp = clean.copy()
            inp[:, lay.target_idx] = model.vocab.mask_id
            out = target_tokens(decode_parallel(model, torch.as_tensor(inp, device=dev), lay, t2i_steps), lay).cpu().numpy()
            truth = clean[:, lay.target_idx]
            acc["t2i"].append((out == truth).ravel())
            cur = data["img"][j][:, : bundle.n_cameras].astype(np.int64).reshape(len(j), -1) + model.vocab.image_offset
            acc["t2i_copy"].append((cur == truth).ravel())
        if "mmu" in tasks:
            clean, lay = build_task_batch(bundle, data, "mmu", j)
            inp = clean.copy()
            inp[:, lay.target_idx] = model.vocab.mask_id
            out = target_tokens(decode_parallel(model, torch.as_tensor(inp, device=dev), lay, mmu_steps), lay).cpu().numpy()
            lo = model.vocab.text_offset
            for row, ref in zip(out, data["answer_str"][j]):
                acc["mmu"].append(np.array([bundle.text_tokenizer.decode(row - lo).strip() == str(ref).strip()]))
    if "mm2a" in tasks and len(idx):
        rest = np.setdiff1d(np.arange(len(data["actions_f"])), idx)
        mean_chunk = data["actions_f"][rest if len(rest) else idx].mean(0)
        res["action_pos_err_mean_chunk_baseline_m"] = float(
            np.linalg.norm(data["actions_f"][idx][..., :3] - mean_chunk[None, :, :3], axis=-1).mean())
    names = {"act_tok": "action_token_acc", "act_bin1": "action_token_acc_within_1bin", "act_err": "action_pos_err_m",
             "act_final": "final_waypoint_to_target_m", "t2i": "t2i_token_acc", "t2i_copy": "t2i_copy_current_baseline_acc",
             "mmu": "mmu_answer_acc", "aux_t": "aux_ball_pos_err_m", "aux_prev": "aux_ball_prev_pos_err_m",
             "aux_disp": "aux_ball_displacement_err_m"}
    for k, v in acc.items():
        if v:
            res[names[k]] = float(np.mean(np.concatenate(v)))
    if acc["act_final"]:  # the states that decide closed-loop success: the gripper already at the ball
        final = np.concatenate(acc["act_final"])
        near = np.linalg.norm(data["actions_f"][idx][:, 0, :3] - data["target_pos_m"][idx], axis=-1) < NEAR_BALL_M
        res["n_eval_near"] = int(near.sum())
        if near.any():
            res["final_waypoint_to_target_near_m"] = float(final[near].mean())
        source = data["source"][idx]
        for k in np.unique(source):
            res[f"final_waypoint_to_target_m_data{int(k)}"] = float(final[source == k].mean())
    return res


# ---------------------------------------------------------------- stage 0
def run_stage0(args, meta: dict[str, Any], device: str) -> tuple[PolicyBundle, dict[str, Any]]:
    rng = np.random.default_rng(args.seed)
    torch.manual_seed(args.seed)
    frames, corpus = [], []
    n_total = 0
    for _, shard, shard_meta in dataset_shards(args.data):
        d = read_shard(shard, shard_meta)
        n_total += len(d["images"])
        corpus += list(d["instructions"]) + list(d["questions"]) + list(d["answers"])
        f = np.concatenate([d["images"].reshape(-1, *d["images"].shape[2:]),
                            d["future_images"].reshape(-1, *d["future_images"].shape[2:])])
        if len(f) > args.max_frames_per_shard:
            f = f[np.sort(rng.choice(len(f), args.max_frames_per_shard, replace=False))]
        frames.append(f)
    frames = np.concatenate(frames)
    perm = np.random.default_rng(args.split_seed).permutation(len(frames))
    n_val = min(512, max(1, len(frames) // 20))
    val_frames, train_frames = frames[perm[:n_val]], frames[perm[n_val:]]
    init = PolicyBundle.load(args.init, "cpu", require_model=False) if args.init else None
    strides = tuple(int(s) for s in (args.strides or "2,2,2").split(","))
    # --init with other --strides: a new VQ-VAE (another grid) under the checkpoint's text tokenizer and model
    new_vq = init is not None and args.strides is not None and strides != tuple(init.image_cfg.strides)
    if init is not None and not new_vq:  # fine-tune its image tokenizer; its text tokenizer (the model's text ids) stays
        if init.image_cfg.image_size_px != int(meta["image_size_px"]):
            raise SystemExit(f"--init {args.init}: its image tokenizer takes {init.image_cfg.image_size_px} px frames, "
                             f"the data has {meta['image_size_px']} px")
        text_tok, icfg, img_tok = init.text_tokenizer, init.image_cfg, init.image_tokenizer
    else:
        text_tok = init.text_tokenizer if new_vq else TextTokenizer.train(corpus, vocab_size=args.text_vocab)
        chans = tuple([32, 64, 96, 96][: len(strides)])
        try:
            icfg = ImageTokenizerConfig(image_size_px=int(meta["image_size_px"]), strides=strides, channels=chans,
                                        codebook_size=init.image_cfg.codebook_size if new_vq else args.codebook_size)
        except ValueError as exc:
            raise SystemExit(f"--strides {args.strides}: {exc}") from None
        img_tok = ImageTokenizer(icfg)
    psnr_before = evaluate_psnr(img_tok, val_frames) if init is not None and not new_vq else None
    log: list = []
    stats = train_image_tokenizer(img_tok, train_frames, args.steps, args.batch_size or 32, args.lr or 1e-3,
                                  args.seed, device, not args.no_progress, log)
    psnr = evaluate_psnr(img_tok, val_frames)
    with torch.no_grad():
        usage = len(np.unique(img_tok.encode(val_frames[:512]).cpu().numpy())) / icfg.codebook_size
    vocab = VocabLayout(text_size=text_tok.vocab_size, image_codebook_size=icfg.codebook_size, action_bins=int(meta["action_bins"]))
    b = meta["action_bounds"]
    action_tok = ActionTokenizer(int(meta["action_bins"]), ActionBounds(tuple(b["low"]), tuple(b["high"])), vocab.action_offset)
    state_tok = make_state_tokenizer(vocab.action_bins, vocab.action_offset)
    if init is not None and init.model is not None:  # the model's own token ids (stage 2 checks them against the data)
        action_tok, state_tok = init.action_tokenizer, init.state_tokenizer
    bundle = PolicyBundle(icfg, img_tok.cpu().eval(), text_tok, action_tok, state_tok,
                          float(meta["chunk_dt_s"]), camera_names=list(meta["camera_names"]),
                          frame_offsets_s=[float(x) for x in meta.get("frame_offsets_s", [0.0])])
    figures = {"image_psnr_db_heldout": psnr, "image_code_usage_heldout": usage, "image_train_psnr_db_last": stats["psnr_db"],
               "text_vocab_size": text_tok.vocab_size, "frames_train": len(train_frames), "frames_heldout": len(val_frames),
               "grid": icfg.grid}
    if init is not None and init.model is not None:  # the policy goes on with the fine-tuned codes
        if new_vq:  # the codes are new: their embedding rows restart from the new codebook, the grid is the new one
            bundle.attach_model(replace(init.model_cfg, grid=icfg.grid), init.model)
            init.model.init_image_embeddings(img_tok.codebook, seed=args.seed)
            figures["new_image_tokenizer"] = f"strides {list(strides)}, grid {icfg.grid} (was {init.image_cfg.grid})"
        else:
            figures["image_psnr_db_heldout_before"] = psnr_before
            bundle.attach_model(init.model_cfg, init.model)
        bundle.info = {k: init.info[k] for k in ("train_config", "history", "stage", "command", "figures") if k in init.info}
        return bundle, {"figures": figures, "n_samples": n_total, "text_size": init.model_cfg.text_size,
                        "log_tail": log[-5:], "init": str(args.init), "history": list(init.info.get("history", []))}
    return bundle, {"figures": figures, "n_samples": n_total, "text_size": text_tok.vocab_size, "log_tail": log[-5:]}


# ---------------------------------------------------------------- stages 1 / 2
def check_data_weights(weights: list[float] | None, n_dirs: int) -> None:
    """``--data-weights``: one finite weight >= 0 per ``--data`` directory (checked before any data is read)."""
    if weights is None:
        return
    if len(weights) != n_dirs:
        raise SystemExit(f"--data-weights: got {len(weights)} weights for {n_dirs} --data directories")
    w = np.asarray(weights, dtype=np.float64)
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise SystemExit(f"--data-weights must be finite and >= 0, got {list(weights)}")


def sampling_probabilities(source: np.ndarray, weights: list[float] | None, n_dirs: int) -> np.ndarray | None:
    """Per-sample draw probabilities from one weight per dataset directory (None: uniform over samples).

    A sample of a directory with weight ``w`` is drawn ``w`` times as often as a sample of weight 1, e.g. to
    favour the newest DAgger round over the bulk of the expert demonstrations."""
    if weights is None:
        return None
    check_data_weights(weights, n_dirs)
    p = np.asarray(weights, dtype=np.float64)[source]
    if p.sum() <= 0:
        raise SystemExit(f"--data-weights {list(weights)} give every training sample weight 0")
    return p / p.sum()


def eval_subset(val_idx: np.ndarray, n: int, seed: int) -> np.ndarray:
    """A seeded random subset of the held-out indices, so every dataset directory is represented in proportion
    (the held-out indices are sorted: their first ``n`` would all come from the first directory)."""
    if len(val_idx) <= n:
        return val_idx
    return np.sort(np.random.default_rng(seed).choice(val_idx, size=n, replace=False))


def lr_at(step: int, tc: TrainConfig) -> float:
    if step < tc.warmup_steps:
        return tc.lr * (step + 1) / tc.warmup_steps
    p = (step - tc.warmup_steps) / max(1, tc.steps - tc.warmup_steps)
    return tc.lr * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * min(1.0, p))))


def run_stage12(args, meta: dict[str, Any], device: str, out: Path):
    from tqdm import tqdm

    resume_path = out / f"resume_stage{args.stage}.pt"
    resume = None
    if args.resume:
        if not resume_path.is_file():
            raise SystemExit(f"--resume: no {resume_path} to resume from")
        resume = torch.load(resume_path, map_location="cpu", weights_only=False)
        bundle = PolicyBundle.from_payload(resume["bundle"], resume_path, "cpu")
        tc = TrainConfig(**{**resume["train_config"], "weights": LossWeights(**resume["train_config"]["weights"])})
        tc = replace(tc, steps=args.steps or tc.steps)
    else:
        if not args.init:
            raise SystemExit(f"stage {args.stage} needs --init: a stage-0 checkpoint (tokenizers) or a stage-1/2 checkpoint")
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
        w = LossWeights.for_stage(args.stage)
        aux_w = (0.5 if bundle.model_cfg.aux_positions and args.stage == 2 else 0.0) if args.w_aux is None else args.w_aux
        w = LossWeights(action=w.action if args.w_action is None else args.w_action,
                        text=w.text if args.w_text is None else args.w_text,
                        image=w.image if args.w_image is None else args.w_image, aux=aux_w)
        tc = TrainConfig(stage=args.stage, steps=args.steps or 2000, batch_size=args.batch_size or 32, lr=args.lr or 3e-4,
                         weight_decay=0.01 if args.weight_decay is None else args.weight_decay,
                         warmup_steps=min(200, max(1, (args.steps or 2000) // 10)), weights=w, seed=args.seed,
                         eval_samples=args.eval_samples, action_label_sigma_bins=args.action_sigma_bins,
                         aux_batch_size=args.aux_batch_size or 0, known_prefix_max_waypoints=args.known_prefix_max,
                         known_prefix_prob=args.known_prefix_prob, aux_known_prob=args.aux_known_prob)
        new_views = (list(args.cameras or meta["camera_names"]), [float(x) for x in meta.get("frame_offsets_s", [0.0])])
        if (list(bundle.camera_names), list(bundle.frame_offsets_s)) != new_views:
            # a checkpoint trained on other views (e.g. one camera, one frame) fine-tuned on this data: its
            # layout becomes the data's (the view embeddings of the new views start from their initial values)
            print(f"views: {bundle.camera_names} x {bundle.frame_offsets_s} -> {new_views[0]} x {new_views[1]}",
                  file=sys.stderr)
            bundle.camera_names, bundle.frame_offsets_s = new_views
    check_data_matches(bundle, meta, args.init or resume_path, list(bundle.camera_names))
    if tc.known_prefix_max_waypoints >= bundle.model_cfg.horizon:
        raise SystemExit(f"--known-prefix-max {tc.known_prefix_max_waypoints} must be below the chunk horizon "
                         f"{bundle.model_cfg.horizon} (the issue's recipe: H/2)")
    torch.manual_seed(tc.seed)
    rng = np.random.default_rng(tc.seed)
    bundle.to(device)
    model = bundle.model
    if args.dropout is not None:  # regularisation for this run only: inference runs in eval mode either way
        for module in model.modules():
            if isinstance(module, torch.nn.Dropout):
                module.p = float(args.dropout)
    data = training_tokens(bundle, args)
    n = len(data["img"])
    train_idx, val_idx = split_indices(n, tc.val_fraction, tc.split_seed)
    if len(train_idx) == 0:
        raise SystemExit("dataset too small: no training samples")
    draw_p = sampling_probabilities(data["source"][train_idx], args.data_weights, len(args.data))
    opt = torch.optim.AdamW(model.parameters(), lr=tc.lr, weight_decay=tc.weight_decay, betas=(0.9, 0.98))
    start, log, wall0 = 0, [], 0.0
    if resume is not None:
        opt.load_state_dict(resume["optimizer"])
        start, log, wall0 = int(resume["step"]), list(resume["log"]), float(resume["wall_s"])
        rng.bit_generator.state = resume["np_rng"]
        torch.set_rng_state(resume["torch_rng"])
    tasks = [t for t in ("mm2a", "t2i", "mmu") if getattr(tc.weights, TASK_WEIGHT[t]) > 0]
    if not tasks:
        raise SystemExit("all loss weights are 0")
    use_amp = device.startswith("cuda") or args.amp
    amp_device = "cuda" if device.startswith("cuda") else "cpu"
    ema: dict[str, float] = {}
    t0 = time.perf_counter()

    def save_resume(step: int) -> None:
        torch.save({"bundle": bundle.payload(), "optimizer": opt.state_dict(), "step": step, "log": log,
                    "np_rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state(),
                    "train_config": asdict(tc), "wall_s": wall0 + time.perf_counter() - t0}, resume_path)

    model.train()
    budget = getattr(args, "time_budget_s", None)
    warm_steps, calib_steps, t_warm = 10, 20, None  # the first steps (allocations, kernel choice) are not timed
    bar = tqdm(range(start, tc.steps), desc=f"stage {tc.stage}", initial=start, total=tc.steps, disable=args.no_progress)
    for step in bar:
        if budget is not None:
            used = time.perf_counter() - t0
            if step == start + warm_steps:
                t_warm = used
            if step == start + warm_steps + calib_steps:
                rate_s = (used - t_warm) / calib_steps
                fit = budget_steps(step, 1, rate_s, budget - used, tc.steps)
                if fit < tc.steps:
                    print(f"--time-budget-s {budget:g}: {rate_s:.3f} s/step, --steps {tc.steps} -> {fit}", file=sys.stderr)
                    tc = replace(tc, steps=fit)
                    bar.total = fit
            if step >= tc.steps or used > budget:
                if step < tc.steps:
                    print(f"--time-budget-s {budget:g}: stopped after {step} steps ({used:.0f} s)", file=sys.stderr)
                    tc = replace(tc, steps=step)
                break
        for g in opt.param_groups:
            g["lr"] = lr_at(step, tc)
        losses = {}
        total = torch.zeros((), device=device)
        for task in tasks:
            bs = tc.batch_size if task == "mm2a" or not tc.aux_batch_size else tc.aux_batch_size
            if draw_p is None:
                idx = rng.choice(train_idx, size=bs, replace=len(train_idx) < bs)
            else:
                idx = rng.choice(train_idx, size=bs, replace=True, p=draw_p)
            with torch.autocast(amp_device, dtype=torch.bfloat16, enabled=use_amp):
                loss, aux = task_loss(bundle, data, task, idx, rng, tc.full_mask_prob_action, device,
                                      tc.action_label_sigma_bins, tc.known_prefix_max_waypoints, tc.known_prefix_prob,
                                      with_aux=True, aux_known_prob=tc.aux_known_prob)
            total = total + getattr(tc.weights, TASK_WEIGHT[task]) * loss
            losses[task] = float(loss.detach())
            if aux is not None and tc.weights.aux > 0:
                total = total + tc.weights.aux * aux
                losses["aux"] = float(aux.detach())
        opt.zero_grad(set_to_none=True)
        total.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), tc.grad_clip)
        opt.step()
        for k, v in losses.items():
            ema[k] = v if k not in ema else 0.98 * ema[k] + 0.02 * v
        if step % 10 == 0 or step == tc.steps - 1:
            bar.set_postfix({f"{k}": f"{v:.3f}" for k, v in ema.items()})
            log.append({"step": step, **{f"loss_{k}": round(v, 5) for k, v in losses.items()}})
        if args.save_every and (step + 1) % args.save_every == 0 and step + 1 < tc.steps:
            save_resume(step + 1)
    wall = wall0 + time.perf_counter() - t0
    save_resume(tc.steps)
    model.eval()
    ev_idx = eval_subset(val_idx, tc.eval_samples, tc.split_seed)
    te = time.perf_counter()
    figures = evaluate(bundle, data, ev_idx, aux_first=bool(bundle.model_cfg.aux_positions) and tc.aux_known_prob > 0)
    figures["eval_wall_s"] = time.perf_counter() - te
    info = {"figures": figures, "n_samples": n, "n_train": int(len(train_idx)), "n_heldout": int(len(val_idx)),
            "final_losses_ema": {k: round(v, 4) for k, v in ema.items()}, "train_config": asdict(tc),
            "train_wall_s": wall, "n_params": model.n_params(), "log_tail": log[-5:]}
    return bundle.to("cpu"), info


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


def resolve_data(args) -> dict[str, Any]:
    """The data's meta from ``--data`` or from existing ``--tokens-cache`` files (which then fill ``args.data``: the
    directories of every cache, in order)."""
    caches = _caches(args)
    if caches and args.stage == 0:
        raise SystemExit("--tokens-cache is for stages 1/2 (stage 0 trains the image tokenizer on the frames themselves)")
    if caches and all(Path(c).is_file() for c in caches):
        headers = []
        for c in caches:
            try:
                headers.append(read_header(c))
            except TokenCacheError as exc:
                raise SystemExit(f"--tokens-cache: {exc}") from None
        paths = [str(Path(d)) for h in headers for d in h["data_paths"]]
        if args.data and [str(Path(d)) for d in args.data] != paths:
            raise SystemExit(f"--tokens-cache {' '.join(caches)} holds the tokens of {paths}, not of --data "
                             f"{args.data}; leave --data out or name another cache file")
        meta = dict(headers[0]["meta"])
        for c, h in zip(caches[1:], headers[1:]):
            for k in ("image_size_px", "chunk_horizon", "chunk_dt_s", "action_bounds", "action_bins", "frame_offsets_s"):
                if h["meta"].get(k) != meta.get(k):
                    raise SystemExit(f"--tokens-cache {c}: its data's {k}={h['meta'].get(k)!r} differs from "
                                     f"{caches[0]}'s {meta.get(k)!r}")
        meta["n_samples"] = sum(int(h["n_samples"]) for h in headers)
        args.data = paths
        return meta
    if len(caches) > 1:
        missing = [c for c in caches if not Path(c).is_file()]
        raise SystemExit(f"--tokens-cache: {missing} do not exist (only a single cache is written from --data)")
    if not args.data:
        raise SystemExit("--data is required (or --tokens-cache naming existing caches, stages 1/2)")
    try:
        return read_metas(args.data)
    except DatasetError as exc:
        raise SystemExit(f"--data: {exc}") from None


def budget_steps(step: int, done: int, elapsed_s: float, left_s: float, planned: int) -> int:
    """The step count that fits the ``left_s`` seconds left, at step ``step``, at the speed of ``done`` steps
    measured in ``elapsed_s``. Never more than ``planned`` and never fewer than ``step`` (the steps made)."""
    if done <= 0 or elapsed_s <= 0:
        return planned
    fit = step + int(max(0.0, left_s) * done / elapsed_s)
    return int(max(step, min(planned, fit)))


def check_data_matches(bundle: PolicyBundle, meta: dict[str, Any], src, cameras: list[str] | None = None) -> None:
    b = meta["action_bounds"]
    at = bundle.action_tokenizer
    if at.bins != int(meta["action_bins"]) or not np.allclose(at.bounds.low, b["low"]) or not np.allclose(at.bounds.high, b["high"]):
        raise CheckpointError(f"{src}: its action tokenizer (bins {at.bins}, bounds {at.bounds}) does not match the "
                              f"dataset's meta.json (bins {meta['action_bins']}, bounds {b})")
    unknown = [c for c in cameras or [] if c not in meta["camera_names"]]
    if unknown:
        raise CheckpointError(f"{src}: cameras {unknown} are not among the data's {meta['camera_names']}")
    n_views = len(cameras or meta["camera_names"]) * len(meta.get("frame_offsets_s", [0.0]))
    if bundle.model_cfg and n_views > bundle.model_cfg.max_views:
        raise CheckpointError(f"{src}: dataset has {n_views} views (cameras x frames) > max_views {bundle.model_cfg.max_views}")
    if bundle.model_cfg and int(meta["chunk_horizon"]) != bundle.model_cfg.horizon:
        raise CheckpointError(f"{src}: model horizon {bundle.model_cfg.horizon} != dataset chunk_horizon {meta['chunk_horizon']}")


# ---------------------------------------------------------------- model card
def write_model_card(path: Path, ckpt: Path, args, meta, info: dict[str, Any], history: list) -> None:
    fig = info.get("figures", {})
    lines = [
        f"# Model card: `{ckpt.name}` (stage {args.stage})", "",
        "MM-ACT-style unified-token policy of mmact-ctrl (`policy/`): one vocabulary "
        "`[special | task + segment | text | image codes | action bins]`, one bidirectional transformer, one tied head.", "",
        "## How it was made", "",
        f"- command: `{info.get('command') or ' '.join(shlex.quote(a) for a in ['python', '-m', 'policy.train', *sys.argv[1:]])}`",
        f"- data: `{' '.join(args.data)}` ({info.get('n_samples')} samples; cameras {meta.get('camera_names')}, "
        f"{meta.get('image_size_px')} px, generator {meta.get('generator', 'scenarios.collect')})",
        f"- steps: {args.steps}, seed {args.seed}, device `{args.device}`",
        f"- wall time: {info.get('train_wall_s', info.get('wall_s', 0.0)):.1f} s (training), "
        f"checkpoint size {ckpt.stat().st_size / 1e6:.2f} MB",
    ]
    if "n_params" in info:
        lines.append(f"- model parameters: {info['n_params']:,}")
    if "train_config" in info:
        lines.append(f"- train config: `{json.dumps(info['train_config'])}`")
    if "final_losses_ema" in info:
        lines += ["", "## Final training losses (EMA, masked-token cross-entropy per task)", ""]
        lines += [f"- {k}: {v}" for k, v in info["final_losses_ema"].items()]
    lines += ["", f"## Evaluation (held-out split, split seed fixed across stages; n={fig.get('n_eval', fig.get('frames_heldout'))})", ""]
    lines += [f"- {k}: {v:.4f}" if isinstance(v, float) else f"- {k}: {v}" for k, v in fig.items()]
    lines += ["", "Metrics: action token accuracy = exact bin match after one-pass decoding; action_pos_err_m = mean "
              "Euclidean TCP position error over the chunk (m); final_waypoint_to_target_m = last waypoint vs target "
              "position; the mean-chunk baseline predicts the average expert chunk; t2i token accuracy after 8-step cosine re-masking (vs the baseline that copies the current "
              "frame's codes); mmu = exact answer match after 4-step decoding.", ""]
    if history:
        lines += ["## Earlier stages", ""]
        for h in history:
            lines.append(f"- stage {h.get('stage')}: `{h.get('command')}` -> {json.dumps(h.get('figures', {}))}")
        lines.append("")
    path.write_text("\n".join(lines))


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(prog="python -m policy.train", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
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
    ap.add_argument("--batch-size", type=int, default=None, help="per task (default 32)")
    ap.add_argument("--aux-batch-size", type=int, default=None,
                    help="stages 1/2: batch of the t2i and mmu tasks (default: --batch-size); small values make a "
                         "fine-tune that still rehearses them cheaper")
    ap.add_argument("--lr", type=float, default=None)
    ap.add_argument("--save-every", type=int, default=500)
    ap.add_argument("--eval-samples", type=int, default=256)
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
    ap.add_argument("--threads", type=int, default=None,
                    help="torch CPU threads (on a shared, busy CPU 1 thread is often much faster than oversubscribing)")
    ap.add_argument("--no-progress", action="store_true")
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
    meta = resolve_data(args)
    check_data_weights(args.data_weights, len(args.data))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ckpt = out / f"stage{args.stage}.pt"
    command = " ".join(shlex.quote(a) for a in ["python", "-m", "policy.train", *sys.argv[1:]]) if argv is None else \
        " ".join(["python", "-m", "policy.train", *argv])
    t0 = time.perf_counter()
    if args.stage == 0:
        args.steps = args.steps or 1500
        bundle, info = run_stage0(args, meta, args.device)
        info["wall_s"] = time.perf_counter() - t0
        history = list(info.pop("history", []))
        if info.get("init") and bundle.info.get("stage") is not None:  # the policy whose tokenizer was refreshed
            history.append({"stage": bundle.info.get("stage"), "command": bundle.info.get("command"),
                            "figures": bundle.info.get("figures", {})})
    else:
        bundle, info = run_stage12(args, meta, args.device, out)
        args.steps = info["train_config"]["steps"]
        history = list(bundle.info.get("history", []))
        prev = dict(bundle.info)
        if prev.get("stage") is not None:
            history.append({"stage": prev.get("stage"), "command": prev.get("command"), "figures": prev.get("figures", {})})
        info["text_size"] = bundle.model_cfg.text_size
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


if __name__ == "__main__":
    main()
