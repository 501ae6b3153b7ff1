"""Configs of the policy package, as frozen dataclasses (sizes, loss weights, schedules).

Everything a checkpoint needs to rebuild its modules is in ``ImageTokenizerConfig`` and
``ModelConfig``; ``TrainConfig`` only describes how a run was trained.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

# Panda joint limits (rad), Franka documentation / example-robot-data URDF. Robot state
# q_rad enters the model as tokens of the action-bin range, quantized over these bounds.
PANDA_Q_LOW_RAD: tuple[float, ...] = (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973)
PANDA_Q_HIGH_RAD: tuple[float, ...] = (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973)


def _from_dict(cls, data: dict[str, Any]):
    """Build a frozen dataclass from a dict, turning lists back into tuples; unknown keys raise."""
    known = {f.name for f in fields(cls)}
    unknown = set(data) - known
    if unknown:
        raise ValueError(f"{cls.__name__}: unknown fields {sorted(unknown)}")
    kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
    return cls(**kwargs)


@dataclass(frozen=True)
class ImageTokenizerConfig:
    """VQ-VAE with an EMA codebook: ``image_size_px`` RGB -> ``grid x grid`` codes and back.

    Attributes:
        image_size_px: square input size in pixels (frames of another size are resized).
        strides: stride of each down-sampling conv; their product is the patch size in px
            ((2, 2, 2) -> 8 px patches -> a 12x12 grid at 96 px; (2, 3) -> 16x16).
        channels: conv channels per down-sampling stage (same length as ``strides``).
        codebook_size: number of codes K (= the image range of the shared vocabulary).
        code_dim: dimension of each code vector.
        ema_decay: EMA decay of the codebook statistics.
        commitment: weight of the commitment loss ``||z - sg(q)||^2``.
        foreground_weight: extra reconstruction weight on pixels that differ from the
            image's median colour (small coloured objects would otherwise be averaged away).
        dead_code_threshold: EMA of a code's assignments per batch below which it is restarted from an
            encoder output (drawn in proportion to its quantization error, so rare content gets codes).
    """

    image_size_px: int = 96
    strides: tuple[int, ...] = (2, 2, 2)
    channels: tuple[int, ...] = (32, 64, 96)
    codebook_size: int = 512
    code_dim: int = 32
    ema_decay: float = 0.99
    commitment: float = 0.25
    foreground_weight: float = 8.0
    dead_code_threshold: float = 1.0

    def __post_init__(self) -> None:
        if len(self.strides) != len(self.channels) or not self.strides:
            raise ValueError("ImageTokenizerConfig: strides and channels must be non-empty and equally long")
        if self.image_size_px % self.patch_px:
            raise ValueError(f"image_size_px {self.image_size_px} is not a multiple of the patch size {self.patch_px}")

    @property
    def patch_px(self) -> int:
        return math.prod(self.strides)

    @property
    def grid(self) -> int:
        """Codes per image side."""
        return self.image_size_px // self.patch_px

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "ImageTokenizerConfig":
        return _from_dict(cls, data)


@dataclass(frozen=True)
class ModelConfig:
    """Bidirectional transformer over one shared vocabulary.

    Attributes:
        text_size / image_codebook_size / action_bins: modality sizes of ``VocabLayout``.
        d_model, n_layers, n_heads, ff_mult, dropout: transformer sizes.
        grid: image codes per side (from the image tokenizer).
        max_text_len: text tokens of an instruction / question (padded / truncated).
        max_answer_len: text tokens of an mmu answer, including its end-of-text token.
        max_views: most camera views one sequence may hold.
        horizon: action chunk length H (waypoints).
        action_dim / state_dim: 7 and 7.
        ball_views: views (cameras x frames) whose balls enter an mm2a query as sub-pixel image positions
            (``policy.ball_detector``: u, v per colour per view, in the state bins); 0 = none (the layouts before
            issue 25).
        ball_colors: ball colours per view (token order of the detector's ``colors``).
        aux_positions: 3-D positions of the instructed ball an mm2a query predicts beside its chunk, as an
            auxiliary masked target in the action bins (1: at t; 2: at t and at the earlier frame); 0 = none.
    """

    text_size: int = 512
    image_codebook_size: int = 512
    action_bins: int = 2048
    d_model: int = 192
    n_layers: int = 4
    n_heads: int = 6
    ff_mult: int = 4
    dropout: float = 0.0
    grid: int = 12
    max_text_len: int = 24
    max_answer_len: int = 8
    max_views: int = 4
    horizon: int = 16
    action_dim: int = 7
    state_dim: int = 7
    ball_views: int = 0
    ball_colors: int = 2
    aux_positions: int = 0

    def __post_init__(self) -> None:
        if self.d_model % self.n_heads:
            raise ValueError(f"d_model {self.d_model} must be divisible by n_heads {self.n_heads}")
        for name in ("grid", "max_text_len", "max_answer_len", "horizon", "action_dim", "state_dim"):
            if not 1 <= getattr(self, name) <= 64:
                raise ValueError(f"ModelConfig.{name} must be in [1, 64], got {getattr(self, name)}")
        if not 0 <= self.ball_views <= self.max_views:
            raise ValueError(f"ModelConfig.ball_views must be in [0, max_views={self.max_views}], got {self.ball_views}")
        if not 1 <= self.ball_colors <= 8:
            raise ValueError(f"ModelConfig.ball_colors must be in [1, 8], got {self.ball_colors}")
        if not 0 <= self.aux_positions <= 4:
            raise ValueError(f"ModelConfig.aux_positions must be in [0, 4], got {self.aux_positions}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "ModelConfig":
        return _from_dict(cls, data)


@dataclass(frozen=True)
class LossWeights:
    """Per-task loss weights: action (mm2a), text (mmu answers), image (t2i future codes), and aux: the mm2a
    query's auxiliary target (the instructed ball's 3-D positions; only models with ``aux_positions > 0``)."""

    action: float = 1.0
    text: float = 0.05
    image: float = 0.05
    aux: float = 0.0

    @classmethod
    def for_stage(cls, stage: int) -> "LossWeights":
        """MM-ACT schedule: stage 1 trains t2i + mmu with the action loss off; stage 2 action 1.0, text/image 0.05."""
        if stage == 1:
            return cls(action=0.0, text=1.0, image=1.0)
        if stage == 2:
            return cls(action=1.0, text=0.05, image=0.05)
        raise ValueError(f"loss weights are defined for stages 1 and 2, got {stage}")


@dataclass(frozen=True)
class TrainConfig:
    """How a stage is trained (recorded in the checkpoint and the model card)."""

    stage: int = 2
    steps: int = 2000
    batch_size: int = 32
    lr: float = 3e-4
    weight_decay: float = 0.01
    warmup_steps: int = 200
    grad_clip: float = 1.0
    weights: LossWeights = LossWeights()
    full_mask_prob_action: float = 0.5  # share of mm2a samples with the whole chunk masked (the one-pass case)
    # action targets as a Gaussian over neighbouring bins (HL-Gauss, Farebrother et al. 2024); 0 = one-hot
    action_label_sigma_bins: float = 16.0
    val_fraction: float = 0.1
    split_seed: int = 1234  # fixed across stages, so every stage holds out the same samples
    eval_samples: int = 256
    seed: int = 0
    aux_batch_size: int = 0  # batch of the t2i and mmu tasks; 0 = batch_size (a cheaper fine-tune keeps them small)
    # inpainting: a share known_prefix_prob of the mm2a samples gets its first U{0..max} waypoints as known tokens
    known_prefix_max_waypoints: int = 0
    known_prefix_prob: float = 0.0
    # aux target (models with aux_positions > 0): a share aux_known_prob of the mm2a samples gets the ball's true
    # positions as known tokens (no aux loss there), so the chunk learns to read them; such a checkpoint decodes in
    # two passes at run time: the positions first, then the chunk given them (policy.decoding.fill_aux)
    aux_known_prob: float = 0.0
