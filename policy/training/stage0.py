"""Stage 0: the tokenizers. Byte-level BPE on the instruction/question/answer strings and the VQ-VAE image quantizer
on the frames (images and future images); no model weights. With ``--init CKPT`` the checkpoint's text tokenizer and
model are kept and its VQ-VAE is fine-tuned on the new frames (or, with other ``--strides``, a new one is trained under
them)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import torch

from policy.action_tokenizer import ActionBounds, ActionTokenizer
from policy.bundle import PolicyBundle, make_state_tokenizer
from policy.config import ImageTokenizerConfig
from policy.dataset import dataset_shards, read_shard
from policy.image_tokenizer import ImageTokenizer, evaluate_psnr, train_image_tokenizer
from policy.text_tokenizer import TextTokenizer
from policy.vocab import VocabLayout


def run_stage0(args, meta: dict[str, Any], device: str) -> tuple[PolicyBundle, dict[str, Any]]:
    """Train the tokenizers on ``args.data``; returns the bundle (with the ``--init`` model, if it has one) and the
    run's info (held-out figures, sample count, log tail)."""
    rng = np.random.default_rng(args.seed)
    torch.manual_seed(args.seed)
    frames, corpus, n_total = read_frames(args, rng)
    perm = np.random.default_rng(args.split_seed).permutation(len(frames))
    n_val = min(512, max(1, len(frames) // 20))
    val_frames, train_frames = frames[perm[:n_val]], frames[perm[n_val:]]
    init = PolicyBundle.load(args.init, "cpu", require_model=False) if args.init else None
    strides = tuple(int(s) for s in (args.strides or "2,2,2").split(","))
    # --init with other --strides: a new VQ-VAE (another grid) under the checkpoint's text tokenizer and model
    new_vq = init is not None and args.strides is not None and strides != tuple(init.image_cfg.strides)
    text_tok, icfg, img_tok = _tokenizers(args, meta, init, new_vq, strides, corpus)
    psnr_before = evaluate_psnr(img_tok, val_frames) if init is not None and not new_vq else None
    log: list = []
    stats = train_image_tokenizer(img_tok, train_frames, args.steps, args.batch_size or 32, args.lr or 1e-3,
                                  args.seed, device, not args.no_progress, log)
    psnr = evaluate_psnr(img_tok, val_frames)
    with torch.no_grad():
        usage = len(np.unique(img_tok.encode(val_frames[:512]).cpu().numpy())) / icfg.codebook_size
    bundle = _stage0_bundle(meta, icfg, img_tok, text_tok, init)
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


def read_frames(args, rng: np.random.Generator) -> tuple[np.ndarray, list[str], int]:
    """``(frames (N, H, W, 3) uint8, text corpus, sample count)`` of ``args.data``: every view of every image and
    future image, at most ``args.max_frames_per_shard`` per shard (a sorted random subset drawn with ``rng``)."""
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
    return np.concatenate(frames), corpus, n_total


def _tokenizers(args, meta: dict[str, Any], init: PolicyBundle | None, new_vq: bool, strides: tuple[int, ...],
                corpus: list[str]) -> tuple[TextTokenizer, ImageTokenizerConfig, ImageTokenizer]:
    """The text tokenizer, image tokenizer config and image tokenizer to train: ``--init``'s own (fine-tuned), or a
    new VQ-VAE (under ``--init``'s text tokenizer when ``new_vq``, else under a BPE trained on ``corpus``)."""
    if init is not None and not new_vq:  # fine-tune its image tokenizer; its text tokenizer (the model's text ids) stays
        if init.image_cfg.image_size_px != int(meta["image_size_px"]):
            raise SystemExit(f"--init {args.init}: its image tokenizer takes {init.image_cfg.image_size_px} px frames, "
                             f"the data has {meta['image_size_px']} px")
        return init.text_tokenizer, init.image_cfg, init.image_tokenizer
    text_tok = init.text_tokenizer if new_vq else TextTokenizer.train(corpus, vocab_size=args.text_vocab)
    chans = tuple([32, 64, 96, 96][: len(strides)])
    try:
        icfg = ImageTokenizerConfig(image_size_px=int(meta["image_size_px"]), strides=strides, channels=chans,
                                    codebook_size=init.image_cfg.codebook_size if new_vq else args.codebook_size)
    except ValueError as exc:
        raise SystemExit(f"--strides {args.strides}: {exc}") from None
    return text_tok, icfg, ImageTokenizer(icfg)


def _stage0_bundle(meta: dict[str, Any], icfg: ImageTokenizerConfig, img_tok: ImageTokenizer, text_tok: TextTokenizer,
                   init: PolicyBundle | None) -> PolicyBundle:
    """The bundle of the trained tokenizers (action and state tokenizers from the data's meta, or ``--init``'s own
    when it has a model: its token ids stay)."""
    vocab = VocabLayout(text_size=text_tok.vocab_size, image_codebook_size=icfg.codebook_size, action_bins=int(meta["action_bins"]))
    b = meta["action_bounds"]
    action_tok = ActionTokenizer(int(meta["action_bins"]), ActionBounds(tuple(b["low"]), tuple(b["high"])), vocab.action_offset)
    state_tok = make_state_tokenizer(vocab.action_bins, vocab.action_offset)
    if init is not None and init.model is not None:  # the model's own token ids (stage 2 checks them against the data)
        action_tok, state_tok = init.action_tokenizer, init.state_tokenizer
    return PolicyBundle(icfg, img_tok.cpu().eval(), text_tok, action_tok, state_tok,
                        float(meta["chunk_dt_s"]), camera_names=list(meta["camera_names"]),
                        frame_offsets_s=[float(x) for x in meta.get("frame_offsets_s", [0.0])])
