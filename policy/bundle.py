"""Everything one checkpoint holds, as live objects: model, tokenizers, layouts.

``PolicyBundle`` is shared by training, inference and the benchmark; it turns raw observations
(frames, strings, joint angles, float actions) into the shared-vocabulary batches of
``policy.sequence`` and back, and converts to / from a checkpoint payload.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from policy.action_tokenizer import ActionBounds, ActionTokenizer
from policy.ball_detector import BallDetectorConfig, BallTokenizer, detect_balls
from policy.checkpoint import (
    CheckpointError, cpu_state, load_checkpoint, load_state_strict, save_checkpoint, tokenizer_dict, tokenizer_from_dict,
)
from policy.config import PANDA_Q_HIGH_RAD, PANDA_Q_LOW_RAD, ImageTokenizerConfig, ModelConfig
from policy.image_tokenizer import ImageTokenizer
from policy.model import MMActModel, vocab_of
from policy.sequence import LayoutBuilder
from policy.text_tokenizer import TextTokenizer


def make_state_tokenizer(action_bins: int, token_offset: int) -> ActionTokenizer:
    """Joint angles (rad) -> tokens of the action-bin range, quantized over the Panda joint limits."""
    return ActionTokenizer(bins=action_bins, bounds=ActionBounds(PANDA_Q_LOW_RAD, PANDA_Q_HIGH_RAD), token_offset=token_offset)


@dataclass
class PolicyBundle:
    image_cfg: ImageTokenizerConfig
    image_tokenizer: ImageTokenizer
    text_tokenizer: TextTokenizer
    action_tokenizer: ActionTokenizer
    state_tokenizer: ActionTokenizer
    chunk_dt_s: float
    model_cfg: ModelConfig | None = None
    model: MMActModel | None = None
    camera_names: list[str] = field(default_factory=lambda: ["front"])
    info: dict[str, Any] = field(default_factory=dict)
    #: capture times of the frames an mm2a query holds, relative to the observation (s, 0 first; e.g. [0, -0.1]):
    #: the views are ordered frame-major, ``[cam0@0, cam1@0, cam0@-0.1, cam1@-0.1]``
    frame_offsets_s: list[float] = field(default_factory=lambda: [0.0])
    #: how the balls are found in the frames (``policy.ball_detector``); it makes the ball tokens of a model with
    #: ``ball_views > 0`` and of every token cache (``policy.token_cache``)
    ball_detector: BallDetectorConfig = field(default_factory=BallDetectorConfig)
    #: frames whose VQ codes enter an mm2a query (the first k of ``frame_offsets_s``); 0 = all of them
    mm2a_image_frames: int = 0
    _builder: LayoutBuilder | None = None

    # ---- construction ---------------------------------------------------
    def attach_model(self, model_cfg: ModelConfig, model: MMActModel | None = None) -> MMActModel:
        if model_cfg.grid != self.image_cfg.grid or model_cfg.image_codebook_size != self.image_cfg.codebook_size:
            raise ValueError("model config grid / codebook size differ from the image tokenizer's")
        if model_cfg.action_bins != self.action_tokenizer.bins:
            raise ValueError("model config action_bins differs from the action tokenizer's")
        if self.text_tokenizer.vocab_size > model_cfg.text_size:
            raise ValueError(f"text tokenizer has {self.text_tokenizer.vocab_size} ids > text_size {model_cfg.text_size}")
        self.model_cfg = model_cfg
        self.model = model if model is not None else MMActModel(model_cfg)
        self.model.cfg = model_cfg  # a layout switch (policy.training.stage12_setup.set_layout) keeps the weights
        self._builder = None
        return self.model

    @property
    def device(self) -> torch.device:
        return self.image_tokenizer.codebook.device

    @property
    def n_cameras(self) -> int:
        return len(self.camera_names)

    @property
    def n_views(self) -> int:
        """Views of an mm2a query: cameras x frames (t2i and mmu see the current frame of each camera only)."""
        return len(self.camera_names) * len(self.frame_offsets_s)

    @property
    def mm2a_image_views(self) -> int:
        """Views whose VQ codes an mm2a query holds: cameras x the first ``mm2a_image_frames`` frames."""
        frames = self.mm2a_image_frames or len(self.frame_offsets_s)
        return len(self.camera_names) * min(frames, len(self.frame_offsets_s))

    def to(self, device: str | torch.device) -> "PolicyBundle":
        self.image_tokenizer.to(device)
        if self.model is not None:
            self.model.to(device)
        return self

    @property
    def builder(self) -> LayoutBuilder:
        if self.model_cfg is None:
            raise RuntimeError("this bundle has no model (stage-0 checkpoint)")
        if self._builder is None:
            self._builder = LayoutBuilder(vocab_of(self.model_cfg), self.model_cfg)
        return self._builder

    # ---- encoders ---------------------------------------------------------
    def text_batch(self, texts, length: int | None = None, end_with_eot: bool = False) -> np.ndarray:
        length = length or self.model_cfg.max_text_len
        return np.stack([self.text_tokenizer.encode_fixed(str(t), length, end_with_eot)[0] for t in texts])

    def image_codes(self, images: np.ndarray, batch: int = 256) -> np.ndarray:
        """uint8 ``(N, V, H, W, 3)`` -> int64 codes ``(N, V, g, g)``."""
        images = np.asarray(images)
        if images.ndim != 5 or images.dtype != np.uint8 or images.shape[-1] != 3:
            raise ValueError(f"images must be uint8 (N, V, H, W, 3), got {images.shape} {images.dtype}")
        n, v = images.shape[:2]
        flat = images.reshape(n * v, *images.shape[2:])
        out = [self.image_tokenizer.encode(flat[i : i + batch]).cpu().numpy() for i in range(0, len(flat), batch)]
        codes = np.concatenate(out) if out else np.zeros((0, self.image_cfg.grid, self.image_cfg.grid), np.int64)
        return codes.reshape(n, v, self.image_cfg.grid, self.image_cfg.grid)

    def ball_tokens(self, images: np.ndarray) -> np.ndarray:
        """uint8 frames ``(N, V, H, W, 3)`` -> ball tokens ``(N, V, colours, 2)`` int64 (``policy.ball_detector``:
        each colour's centroid u, v in the state bins over the frame's width, ``<|pad|>`` where not seen)."""
        images = np.asarray(images)
        if images.ndim != 5 or images.dtype != np.uint8 or images.shape[-1] != 3:
            raise ValueError(f"images must be uint8 (N, V, H, W, 3), got {images.shape} {images.dtype}")
        uv, _ = detect_balls(images, self.ball_detector)
        vocab = vocab_of(self.model_cfg) if self.model_cfg else None
        offset = vocab.action_offset if vocab else self.action_tokenizer.token_offset
        tok = BallTokenizer(int(images.shape[-2]), self.action_tokenizer.bins, offset,
                            vocab.pad_id if vocab else 0)
        return tok.encode(uv)

    def aux_tokens(self, pos_m: np.ndarray) -> np.ndarray:
        """3-D positions ``(..., 3)`` (m) -> tokens ``(..., 3)`` of the action bins of x, y, z."""
        pos = np.asarray(pos_m, dtype=np.float64)
        full = np.zeros((*pos.shape[:-1], 7))
        full[..., :3] = pos
        full[..., 6] = self.action_tokenizer.low[6]
        return self.action_tokenizer.encode(full)[0][..., :3]

    def aux_positions_m(self, bins: np.ndarray) -> np.ndarray:
        """(Fractional) bin indices ``(..., 3)`` of the aux target -> positions (m), bin centres for integers."""
        b = np.asarray(bins, dtype=np.float64)
        full = np.zeros((*b.shape[:-1], 7))
        full[..., :3] = b
        return self.action_tokenizer.decode_fractional(full)[..., :3]

    def state_tokens(self, q_rad: np.ndarray) -> np.ndarray:
        return self.state_tokenizer.encode(np.asarray(q_rad, dtype=np.float64))[0]

    def action_tokens(self, actions: np.ndarray) -> np.ndarray:
        return self.action_tokenizer.encode(np.asarray(actions, dtype=np.float64))[0]

    # ---- persistence ------------------------------------------------------
    def payload(self, info: dict[str, Any] | None = None) -> dict[str, Any]:
        out = {
            "model_config": self.model_cfg.to_dict() if self.model_cfg else None,
            "image_tokenizer_config": self.image_cfg.to_dict(),
            "action_tokenizer": tokenizer_dict(self.action_tokenizer),
            "state_tokenizer": tokenizer_dict(self.state_tokenizer),
            "text_tokenizer_json": self.text_tokenizer.to_json(),
            "chunk_dt_s": float(self.chunk_dt_s),
            "camera_names": list(self.camera_names),
            "frame_offsets_s": [float(x) for x in self.frame_offsets_s],
            "model_state": cpu_state(self.model) if self.model is not None else None,
            "image_tokenizer_state": cpu_state(self.image_tokenizer),
            "info": dict(info if info is not None else self.info),
        }
        cfg = self.model_cfg
        if (cfg and (cfg.ball_views or cfg.aux_positions)) or self.mm2a_image_frames or self.ball_detector != BallDetectorConfig():
            # issue 25's layouts; a checkpoint made before them re-saves byte for byte without these keys
            out["ball_detector"] = self.ball_detector.to_dict()
            out["mm2a_image_frames"] = int(self.mm2a_image_frames)
        return out

    def save(self, path: str | Path, info: dict[str, Any] | None = None) -> Path:
        return save_checkpoint(path, self.payload(info))

    @classmethod
    def load(cls, path: str | Path, device: str = "cpu", require_model: bool = True) -> "PolicyBundle":
        """Load and verify a checkpoint file (``CheckpointError`` names any problem)."""
        return cls.from_payload(load_checkpoint(path), path, device, require_model)

    @classmethod
    def from_payload(cls, p: dict[str, Any], path: str | Path = "<payload>", device: str = "cpu",
                     require_model: bool = True) -> "PolicyBundle":
        try:
            image_cfg = ImageTokenizerConfig.from_dict(p["image_tokenizer_config"])
            model_cfg = ModelConfig.from_dict(p["model_config"]) if p["model_config"] is not None else None
            text_tok = TextTokenizer.from_json(p["text_tokenizer_json"])
            action_tok = tokenizer_from_dict(p["action_tokenizer"])
            state_tok = tokenizer_from_dict(p["state_tokenizer"])
            detector = BallDetectorConfig.from_dict(p["ball_detector"]) if p.get("ball_detector") else BallDetectorConfig()
        except CheckpointError:
            raise
        except Exception as e:
            raise CheckpointError(f"{path}: invalid config or tokenizer entry: {type(e).__name__}: {e}") from None
        img = ImageTokenizer(image_cfg)
        load_state_strict(img, p["image_tokenizer_state"], "image tokenizer", path)
        img.eval()
        b = cls(image_cfg, img, text_tok, action_tok, state_tok, float(p["chunk_dt_s"]),
                camera_names=list(p.get("camera_names") or ["front"]), info=dict(p.get("info") or {}),
                frame_offsets_s=[float(x) for x in (p.get("frame_offsets_s") or [0.0])], ball_detector=detector,
                mm2a_image_frames=int(p.get("mm2a_image_frames") or 0))
        if model_cfg is None or p["model_state"] is None:
            if require_model:
                raise CheckpointError(f"{path} holds no model weights (a stage-0 image/text tokenizer checkpoint)")
        else:
            if model_cfg.action_bins != action_tok.bins or action_tok.token_offset != vocab_of(model_cfg).action_offset:
                raise CheckpointError(f"{path}: action tokenizer (bins {action_tok.bins}, offset {action_tok.token_offset}) "
                                      f"does not match the model vocabulary")
            try:
                model = b.attach_model(model_cfg)
            except ValueError as e:
                raise CheckpointError(f"{path}: {e}") from None
            load_state_strict(model, p["model_state"], "model", path)
            model.eval()
        return b.to(device)


def untrained_bundle(model_cfg: ModelConfig | None = None, image_cfg: ImageTokenizerConfig | None = None,
                     corpus: list[str] | None = None, action_bounds: ActionBounds | None = None,
                     chunk_dt_s: float = 0.1, seed: int = 0) -> PolicyBundle:
    """A randomly initialised bundle (tests, latency benchmarks without a checkpoint).

    The text tokenizer is trained on ``corpus`` (a few instruction templates by default) and the
    model's text range is sized to it; grid / codebook / bins follow ``image_cfg`` / ``model_cfg``.
    """
    torch.manual_seed(seed)
    image_cfg = image_cfg or ImageTokenizerConfig()
    corpus = corpus or [f"{v} the {c} {n}" for v in ("reach", "touch", "move to") for c in ("red", "green", "blue", "yellow")
                        for n in ("ball", "sphere")] + ["where is the red ball?", "left", "right", "center"]
    text_tok = TextTokenizer.train(corpus, vocab_size=300)
    base = model_cfg or ModelConfig()
    from dataclasses import replace

    model_cfg = replace(base, text_size=text_tok.vocab_size, image_codebook_size=image_cfg.codebook_size, grid=image_cfg.grid)
    vocab = vocab_of(model_cfg)
    action_tok = ActionTokenizer(model_cfg.action_bins, action_bounds or ActionBounds(), vocab.action_offset)
    b = PolicyBundle(image_cfg, ImageTokenizer(image_cfg).eval(), text_tok, action_tok,
                     make_state_tokenizer(model_cfg.action_bins, vocab.action_offset), chunk_dt_s)
    b.attach_model(model_cfg).eval()
    return b
