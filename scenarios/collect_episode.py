"""One demonstration episode of ``scenarios.collect``: the scene drawn (and redrawn off a held-out region), the arm's
random start, the QP tracking the expert's (or a DAgger driver's) chunks tick by tick, and the samples assembled,
each labelled with the expert's chunk for its frame.

The episode's generator ``default_rng([seed, 7])`` is drawn in a fixed order: the object count (``objects=0``), the
motion kind (a mix), the start perturbation, then at each sample its question and (with a driver) which source drives.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from controllers.robot_description import HOME_Q_RAD, JointLimits
from mmact_ctrl.config import StackConfig
from mmact_ctrl.controller import HybridController
from mmact_ctrl.loop import observe
from scenarios.world.expert import ExpertConfig, ScriptedExpert, expert_actions, lead_velocity_m_s
from scenarios.world.factory import make_world
from scenarios.world.panda_scene import TARGET_COLORS

if TYPE_CHECKING:
    from mmact_ctrl.chunk import ChunkSource, Observation
    from scenarios.collect import CollectConfig
    from scenarios.world.sim_world import SimWorld

#: single motions a collection may use, and the mixes.
MOTIONS: tuple[str, ...] = ("static", "linear", "reversal", "swerve", "random_walk", "jump")
MOTION_CHOICES: tuple[str, ...] = (*MOTIONS, "mixed", "all")
#: the lists of an episode's samples (the arrays of a shard), in this order
SAMPLE_KEYS: tuple[str, ...] = ("images", "future_images", "q_rad", "actions", "instructions", "questions", "answers",
                                "target_index", "target_pos_m", "target_prev_pos_m")


def draw_motion(motion: str, rng: np.random.Generator) -> str:
    """The motion kind of one episode."""
    if motion == "mixed":
        return "linear" if rng.random() < 1 / 3 else "static"
    if motion == "all":
        return "static" if rng.random() < 1 / 3 else str(rng.choice(MOTIONS[1:]))
    return motion


def in_box(pos_m: np.ndarray, box_m: tuple[float, ...]) -> bool:
    """Whether ``pos_m``'s x, y lie in ``box_m = (x0, x1, y0, y1)``."""
    return bool(box_m) and box_m[0] <= pos_m[0] <= box_m[1] and box_m[2] <= pos_m[1] <= box_m[3]


def question_answer(rng: np.random.Generator, objects_pos_m: np.ndarray, target_index: int) -> tuple[str, str]:
    """A question about the scene whose answer a single frame shows."""
    colors = TARGET_COLORS[: len(objects_pos_m)]
    i = int(rng.integers(len(colors)))
    p = objects_pos_m[i]
    kind = int(rng.integers(3 if len(colors) == 2 else 2))
    if kind == 0:  # +y is the robot's left
        side = "left" if p[1] > 0.07 else "right" if p[1] < -0.07 else "center"
        return f"where is the {colors[i]} ball?", side
    if kind == 1:
        return f"is the {colors[i]} ball high or low?", "high" if p[2] > 0.3 else "low"
    closer = int(np.argmin(np.linalg.norm(objects_pos_m[:, :2], axis=1)))
    return "which ball is closer to the robot?", colors[closer]


@dataclass(frozen=True)
class EpisodeTicks:
    """An episode's schedule, in world steps of ``dt_s``.

    Attributes:
        dt_s: the world's physics step, s.
        duration_s: episode length: samples (and their earlier frames) are taken before it.
        n_ticks: steps of the episode and of the last sample's future frame.
        every_ticks: steps between samples.
        future_ticks: steps from a sample to its future frame.
        gap_ticks: steps from a sample's earlier frame to the sample (0: no earlier frame).
    """

    dt_s: float
    duration_s: float
    n_ticks: int
    every_ticks: int
    future_ticks: int
    gap_ticks: int

    @classmethod
    def of(cls, cfg: CollectConfig, dt_s: float) -> EpisodeTicks:
        return cls(dt_s=dt_s, duration_s=cfg.duration_s, n_ticks=int(round((cfg.duration_s + cfg.future_dt_s) / dt_s)),
                   every_ticks=int(round(cfg.sample_every_s / dt_s)), future_ticks=int(round(cfg.future_dt_s / dt_s)),
                   gap_ticks=int(round(cfg.frame_gap_s / dt_s)))

    def is_sample(self, k: int) -> bool:
        """Whether a sample is taken at step ``k``."""
        return k % self.every_ticks == 0 and k * self.dt_s < self.duration_s - 1e-9

    def is_earlier_frame(self, k: int) -> bool:
        """Whether step ``k`` is a sample's earlier frame (``gap_ticks`` before it)."""
        return bool(self.gap_ticks) and self.is_sample(k + self.gap_ticks)


@dataclass(frozen=True)
class PendingSample:
    """A sample taken at step ``tick``, assembled once the episode has its future frame."""

    tick: int
    obs: Observation
    question: str
    answer: str


def _episode_world(cfg: CollectConfig, seed: int, rng: np.random.Generator, world_cache: dict) -> SimWorld:
    """The episode's scene (one per object count and motion kind in ``world_cache``) reset for ``seed``; a scene
    whose instructed ball starts in ``cfg.holdout_box_m`` is redrawn."""
    n_objects = cfg.objects or (1 if rng.random() < 1 / 3 else 2)
    kind = draw_motion(cfg.motion, rng)
    key = (n_objects, kind)
    if key not in world_cache:
        world_cache[key] = make_world(kind, cfg.speed_m_s, n_objects=n_objects, plane_z_m=cfg.plane_z_m,
                                      image_size_px=cfg.image_size_px, cameras=cfg.cameras)
    world = world_cache[key]
    world.reset(seed)
    attempt = 0
    while in_box(world.target_pos_m(), cfg.holdout_box_m):  # a held-out region: draw another scene
        attempt += 1
        if attempt > 1000:
            raise RuntimeError(f"holdout_box_m {cfg.holdout_box_m} covers every scene of seed {seed}")
        world.reset(seed + 10_000_000 * attempt)
    return world


def _random_start(cfg: CollectConfig, world: SimWorld, rng: np.random.Generator) -> None:
    """Perturb the home pose (the world's own reset puts the arm at home), 0.1 rad inside the joint limits."""
    lim = JointLimits().arrays()
    q0 = np.clip(np.asarray(HOME_Q_RAD) + rng.normal(0.0, cfg.start_noise_rad, 7), lim["q_min_rad"] + 0.1, lim["q_max_rad"] - 0.1)
    world.set_arm_state(q0)


def _episode_controller(cfg: CollectConfig, world: SimWorld, world_cache: dict) -> HybridController:
    """The controller (one in ``world_cache``), reset to the arm's start.

    The arm only has to move like a policy-driven arm: the QP tracking the expert's chunks (replanned at every sample,
    no latency) does that at a fraction of the hybrid stack's cost."""
    if "controller" not in world_cache:
        stack = StackConfig(mode="open_loop", use_mpc=False, duration_s=cfg.duration_s + cfg.future_dt_s, latency_ms=0.0)
        world_cache["controller"] = HybridController(stack)
    controller = world_cache["controller"]
    controller.reset(world.state().q_rad)
    return controller


def _episode_driver(cfg: CollectConfig, world_cache: dict) -> ChunkSource | None:
    """DAgger: the policy whose chunks may drive the arm (one in ``world_cache``); None without one."""
    if not cfg.driver_prob > 0:
        return None
    if "driver" not in world_cache:
        from mmact_ctrl.policy_source import PolicyChunkSource

        world_cache["driver"] = PolicyChunkSource(cfg.driver_checkpoint)
    return world_cache["driver"]


def _observe_sample(world: SimWorld, controller: HybridController, t: float, k: int, ticks: EpisodeTicks,
                    frames: dict[int, np.ndarray], target_at: dict[int, np.ndarray]) -> Observation:
    """The observation of the sample at step ``k``, with its earlier frame when the episode has one by then."""
    gap = ticks.gap_ticks
    early = gap and k >= gap
    return observe(world, controller, t, with_image=True, target_prev_pos_m=target_at[k - gap] if early else None,
                   frame_gap_s=gap * ticks.dt_s if early else 0.0, prev_image=frames[k - gap] if early else None)


def _step(world: SimWorld, controller: HybridController, k: int, t: float) -> None:
    """One physics step under the controller's torque; the target is measured every 10th step."""
    if k % 10 == 0:
        controller.perceive(t, world.measure_target())
    state = world.state()
    out = controller.tick(t, state.q_rad, state.dq_rad_s)
    world.step(out.tau_nm, out.gripper_m)


def _run_ticks(cfg: CollectConfig, world: SimWorld, controller: HybridController, expert: ChunkSource,
               driver: ChunkSource | None, rng: np.random.Generator,
               ticks: EpisodeTicks) -> tuple[dict[int, np.ndarray], list[PendingSample]]:
    """Step the episode: (the frames by step: earlier, sample and future ones; the samples taken). At each sample the
    arm replans, from ``driver`` with probability ``cfg.driver_prob``, from ``expert`` otherwise."""
    frames: dict[int, np.ndarray] = {}
    target_at: dict[int, np.ndarray] = {}  # the instructed ball where an earlier frame was taken
    pending: list[PendingSample] = []
    for k in range(ticks.n_ticks + 1):
        t = k * ticks.dt_s
        if ticks.is_earlier_frame(k):
            frames[k], target_at[k] = world.render(), world.target_pos_m().copy()
        if ticks.is_sample(k):
            obs = _observe_sample(world, controller, t, k, ticks, frames, target_at)
            frames[k] = obs.image
            q, a = question_answer(rng, world.objects_pos_m(), world.target_index)
            pending.append(PendingSample(tick=k, obs=obs, question=q, answer=a))
            drive = driver if driver is not None and rng.random() < cfg.driver_prob else expert
            controller.activate(drive.plan(obs), t, controller.target_estimate(t))
        if any(p.tick + ticks.future_ticks == k for p in pending) and k not in frames:
            frames[k] = world.render()
        if k == ticks.n_ticks:
            break
        _step(world, controller, k, t)
    return frames, pending


def _assemble(world: SimWorld, expert_cfg: ExpertConfig, ticks: EpisodeTicks, frames: dict[int, np.ndarray],
              pending: list[PendingSample]) -> dict[str, list]:
    """The samples as lists (``SAMPLE_KEYS``): the frames, the future frame, the state and the expert's label."""
    gap = ticks.gap_ticks
    samples: dict[str, list] = {key: [] for key in SAMPLE_KEYS}
    for p in pending:
        k, obs = p.tick, p.obs
        if gap:  # [current views, earlier views]; the first sample has no earlier frame: it repeats the current one
            samples["images"].append(np.concatenate([frames[k], frames[k - gap] if k >= gap else frames[k]]))
        else:
            samples["images"].append(frames[k])
        samples["future_images"].append(frames[k + ticks.future_ticks])
        samples["q_rad"].append(obs.q_rad.astype(np.float32))
        vel = lead_velocity_m_s(expert_cfg, obs)
        samples["actions"].append(expert_actions(expert_cfg, obs.ee_pos_m, obs.target_pos_m, vel).astype(np.float32))
        samples["instructions"].append(obs.instruction)
        samples["questions"].append(p.question)
        samples["answers"].append(p.answer)
        samples["target_index"].append(world.target_index)
        samples["target_pos_m"].append(obs.target_pos_m.astype(np.float32))
        # where the ball was in the earlier frame (the first sample repeats the current frame: its position)
        prev = obs.target_prev_pos_m if obs.target_prev_pos_m is not None else obs.target_pos_m
        samples["target_prev_pos_m"].append(np.asarray(prev).astype(np.float32))
    return samples


def collect_episode(cfg: CollectConfig, index: int, world_cache: dict) -> dict[str, list]:
    """Run one episode and return its samples as lists."""
    seed = cfg.seed + index
    rng = np.random.default_rng([seed, 7])
    world = _episode_world(cfg, seed, rng, world_cache)
    _random_start(cfg, world, rng)
    controller = _episode_controller(cfg, world, world_cache)
    box = dict(workspace_low_m=tuple(world.target.workspace_low_m), workspace_high_m=tuple(world.target.workspace_high_m))
    expert_cfg = ExpertConfig(lead=cfg.expert_lead, **box)
    expert = ScriptedExpert(expert_cfg)
    driver = _episode_driver(cfg, world_cache)
    ticks = EpisodeTicks.of(cfg, world.dt_s)
    frames, pending = _run_ticks(cfg, world, controller, expert, driver, rng, ticks)
    return _assemble(world, expert_cfg, ticks, frames, pending)
