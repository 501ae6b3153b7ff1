"""The one place that builds the MuJoCo world and the scripted expert from plain settings.

The CLI, the sweep, the data collector and tools that must not import ``scenarios`` directly
(``mmact_ctrl.bench`` loads them by the name ``scenarios.world.factory:make_world``) all use these.
"""

from __future__ import annotations

from scenarios.world.expert import ExpertConfig, ScriptedExpert, expert_tokenizer
from scenarios.world.panda_scene import SceneConfig
from scenarios.world.sim_world import SimWorld
from scenarios.world.tasks.registry import task_by_name

#: height (m) of the balls in the learned policy's scenes (``scenarios.collect --plane-z-m``): from its one
#: camera a ball's depth is only determined when all balls lie at one height.
POLICY_PLANE_Z_M = 0.1


def policy_scene_plane_z_m(checkpoint_info: dict) -> float:
    """The ball height (m) of a policy checkpoint's training scenes: what ``scenarios.collect --plane-z-m`` it was
    trained on (recorded by ``policy.train`` as ``info["scene"]``; 0 = the full 3-D workspace); a checkpoint that
    does not record it (the shipped planar one) gets ``POLICY_PLANE_Z_M``."""
    scene = checkpoint_info.get("scene") or {}
    return float(scene.get("plane_z_m", POLICY_PLANE_Z_M))


def policy_scene(source) -> dict:
    """``make_world`` settings of a learned policy's evaluation scenes: two balls, the checkpoint's cameras and
    its training plane (``policy_scene_plane_z_m``)."""
    return dict(n_objects=2, plane_z_m=policy_scene_plane_z_m(source.policy.bundle.info),
                cameras=tuple(source.camera_names))


def make_world(target: str = "linear", speed_m_s: float = 0.2, noise_m: float = 0.002, dropout: float = 0.1,
               n_objects: int = 1, plane_z_m: float = 0.0, instruction: str | None = None,
               image_size_px: int = 96, cameras: tuple[str, ...] = ("front",), task: str = "reach",
               clearance_mm: float = 1.0) -> SimWorld:
    """The Panda scene of ``task`` (``scenarios.world.tasks``) with its ``n_objects`` things moving as ``target``:
    reach's balls (over a plane at ``plane_z_m`` if > 0), pick's carrier, insert's fixture (``clearance_mm``)."""
    spec_task = task_by_name(task)
    settings = dict(n_objects=n_objects, image_size_px=image_size_px, camera_names=tuple(cameras), task=task,
                    clearance_mm=clearance_mm)
    scene = SceneConfig(**{**settings, **spec_task.scene_overrides})  # what the task's scene needs wins
    return spec_task.world_class(scene, spec_task.target_spec(target, speed_m_s, plane_z_m), noise_m=noise_m,
                                 dropout=dropout, instruction=instruction)


def make_expert(bins: int = 2048, horizon: int = 16, dt_s: float = 0.1, lead: str = "none",
                world: SimWorld | None = None, task: str | None = None):
    """The scripted expert of ``task`` (default: the task of ``world``'s scene, else reach)."""
    if task is None:
        task = world.scene.task if world is not None else "reach"
    return task_by_name(task).make_expert(bins=bins, horizon=horizon, dt_s=dt_s, lead=lead, world=world)


def make_reach_expert(bins: int = 2048, horizon: int = 16, dt_s: float = 0.1, lead: str = "none",
                      world: SimWorld | None = None) -> ScriptedExpert:
    """The scripted expert, its chunks quantized through the shared action tokenizer (bins=0: not quantized);
    ``lead``: ``"none"`` aims where the target is, ``"velocity"`` where two frames say it will be (reflected at the
    walls of ``world``'s target workspace when a world is given)."""
    tokenizer = expert_tokenizer(bins)
    box = {}
    if world is not None:
        box = dict(workspace_low_m=tuple(world.target.workspace_low_m), workspace_high_m=tuple(world.target.workspace_high_m))
    return ScriptedExpert(ExpertConfig(horizon=horizon, dt_s=dt_s, lead=lead, **box), tokenizer)
