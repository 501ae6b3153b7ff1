"""Named constructors of worlds and chunk sources, for tools that must not import ``scenarios``
directly (``mmact_ctrl.bench`` loads them by the name ``scenarios.factory:make_world``)."""

from __future__ import annotations

from policy.action_tokenizer import ActionTokenizer
from policy.vocab import VocabLayout
from scenarios.expert import ExpertConfig, ScriptedExpert
from scenarios.panda_scene import SceneConfig
from scenarios.sim_world import SimWorld
from scenarios.targets import TargetSpec


def make_world(target: str = "linear", speed_m_s: float = 0.2, noise_m: float = 0.002, dropout: float = 0.1,
               n_objects: int = 1) -> SimWorld:
    """The default MuJoCo Panda scene with one moving target."""
    return SimWorld(SceneConfig(n_objects=n_objects), TargetSpec(kind=target, speed_m_s=speed_m_s), noise_m=noise_m,
                    dropout=dropout)


def make_expert(bins: int = 2048, horizon: int = 16, dt_s: float = 0.1) -> ScriptedExpert:
    """The scripted expert, its chunks quantized through the shared action tokenizer (bins=0: not quantized)."""
    tokenizer = ActionTokenizer(bins=bins, token_offset=VocabLayout(action_bins=bins).action_offset) if bins else None
    return ScriptedExpert(ExpertConfig(horizon=horizon, dt_s=dt_s), tokenizer)
