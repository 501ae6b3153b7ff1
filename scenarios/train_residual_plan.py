"""The residual's training episodes (``python -m scenarios.train_residual``): which rollouts to collect (source,
target family, speed, replanning rate, expert lead, seed), and the constants they are drawn from."""

from __future__ import annotations

import inspect
from dataclasses import dataclass

import numpy as np

#: the first training seed: evaluation (the CLI, the sweep) uses seeds 0..999.
TRAIN_SEED0 = 10_000
SPEEDS_M_S = (0.1, 0.2, 0.3, 0.4)
REPLAN_HZ = (1.0, 2.0, 5.0)
#: the new families, used when ``scenarios.world.targets.KINDS`` has them.
MOVING_KINDS = ("linear", "circle", "random_walk", "jump", "reversal", "accelerating", "swerve")
#: the rate samples are taken at (the perception rate the executor runs at), Hz.
SAMPLE_HZ = 100.0


def available_kinds() -> tuple[str, ...]:
    """The moving target families of ``scenarios.world.targets.KINDS`` at run time (``static`` excluded)."""
    from scenarios.world.targets import KINDS

    return tuple(k for k in KINDS if k != "static")


def expert_leads() -> tuple[str, ...]:
    """The expert's ``lead`` settings if ``make_expert`` takes one, else ``("",)`` (no keyword)."""
    from scenarios.world.factory import make_expert

    return ("velocity", "none") if "lead" in inspect.signature(make_expert).parameters else ("",)


@dataclass(frozen=True)
class EpisodeSpec:
    """One rollout: ``source`` (expert | policy), target ``kind`` at ``speed_m_s``, ``replan_hz``, expert
    ``lead`` ("" = make_expert's default), ``seed``."""

    index: int
    source: str
    kind: str
    speed_m_s: float
    replan_hz: float
    lead: str
    seed: int


def plan_episodes(episodes: int, policy_episodes: int = 0, kinds: tuple[str, ...] | None = None,
                  static_fraction: float = 0.1, none_lead_fraction: float = 0.25, seed0: int = TRAIN_SEED0,
                  speeds: tuple[float, ...] = SPEEDS_M_S, replan_hz: tuple[float, ...] = REPLAN_HZ,
                  plan_seed: int = 0) -> list[EpisodeSpec]:
    """The rollouts to collect: ``episodes`` expert ones then ``policy_episodes`` policy ones, seeds ``seed0 + i``.

    Families cycle through ``kinds`` (default :func:`available_kinds`), a share ``static_fraction`` is static;
    speed and replanning rate are drawn uniformly from ``speeds`` and ``replan_hz``; with an expert that has a
    ``lead`` keyword a share ``none_lead_fraction`` of the expert episodes uses ``lead="none"``, the rest
    ``"velocity"``.
    """
    if seed0 < TRAIN_SEED0:
        raise ValueError(f"training seeds must be >= {TRAIN_SEED0} (evaluation uses 0..999), got seed0={seed0}")
    kinds = tuple(kinds) if kinds else available_kinds()
    rng = np.random.default_rng(plan_seed)
    leads = expert_leads()
    total = episodes + policy_episodes
    is_static = rng.permutation(total) < int(round(static_fraction * total))
    specs, moving = [], 0
    for i in range(total):
        source = "expert" if i < episodes else "policy"
        if is_static[i]:
            kind = "static"
        else:
            kind, moving = kinds[moving % len(kinds)], moving + 1
        lead = leads[0] if len(leads) == 1 or rng.uniform() >= none_lead_fraction else leads[1]
        specs.append(EpisodeSpec(index=i, source=source, kind=kind, speed_m_s=float(rng.choice(speeds)),
                                 replan_hz=float(rng.choice(replan_hz)), lead=lead if source == "expert" else "",
                                 seed=seed0 + i))
    return specs
