"""The one place that turns a ``--source`` setting into a chunk source and the scene it runs in.

``--source`` takes

- ``policy``: the shipped unified-token policy (``--checkpoint`` for another);
- ``expert``: the scripted expert (``--expert-lead``, ``--bins``, ``--horizon``, ``--chunk-dt-s``);
- ``module.path:factory`` or ``path/to/file.py:factory``: any callable returning a chunk source, called with the
  ``--source-arg key=value`` settings (``mmact_ctrl.sources.loader``);
- ``lerobot:DIR[:episode]``: a LeRobot dataset's recorded actions replayed as chunks (``mmact_ctrl.sources.replay``);
- ``ws://HOST:PORT``: a policy server speaking openpi's protocol (``mmact_ctrl.sources.openpi``), in the convention
  it was trained in: ``--preset libero|droid|mmact|FILE.json`` and the pieces' own switches (``--obs-mapping``,
  ``--action-space``, ``--gripper``, ``--delta-from``, ``--action-rotation``, ``--action-scale``, ``--action-clip``,
  ``--chunk-dt-s``, ``--image-rotation``), unless the server declares them itself, as ``python -m scenarios.serve``
  does. Before the first episode :func:`connect_check` sends it one observation and says what was configured.

The moving_target, sweep, faults and serve commands all build their sources here, so a source from anywhere gets the
same study, the same safety checks and the same report.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

from mmact_ctrl.sources.spec import SourceSpec

#: the sources built in by name
BUILTIN_SOURCES: tuple[str, ...] = ("policy", "expert")


def source_kind(spec: str) -> str:
    """``policy``, ``expert``, ``remote`` (a ``ws://`` URL), ``replay`` (``lerobot:DIR``) or ``plugin``
    (``module:factory``)."""
    from mmact_ctrl.sources.loader import is_plugin_spec
    from mmact_ctrl.sources.replay import is_replay_spec

    if spec in BUILTIN_SOURCES:
        return spec
    if is_replay_spec(spec):
        return "replay"
    if spec.startswith(("ws://", "wss://")):
        return "remote"
    if is_plugin_spec(spec):
        return "plugin"
    raise ValueError(f"--source {spec!r} is none of policy, expert, module.path:factory, file.py:factory, "
                     "lerobot:DIR[:episode], ws://HOST:PORT")


def source_spec_arg(text: str) -> str:
    """argparse ``type`` of ``--source``: the setting if it has one of the accepted forms (one-line error if not)."""
    try:
        source_kind(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


#: switches that apply to some kinds of source only: argparse dest -> (the switch, the kinds it applies to)
ONLY_FOR: dict[str, tuple[str, tuple[str, ...]]] = {
    "checkpoint": ("--checkpoint", ("policy",)), "action_steps": ("--action-steps", ("policy",)),
    "refine_bins": ("--refine-bins", ("policy",)), "expert_lead": ("--expert-lead", ("expert",)),
    "horizon": ("--horizon", ("expert",)), "chunk_dt_s": ("--chunk-dt-s", ("expert", "remote")),
    "args": ("--source-arg", ("plugin",)),
}
#: the convention's switches (a ``ws://`` source only): SourceSettings field -> ConventionSwitches field
CONVENTION_FIELDS: dict[str, str] = {
    "preset": "preset", "obs_mapping": "obs_mapping", "action_space": "kind", "gripper": "gripper",
    "delta_from": "delta_from", "action_rotation": "rotation", "action_scale": "scale", "action_clip": "clip",
    "image_rotation": "image_rotation_deg",
}
_KIND_WORDS = {"policy": "--source policy", "expert": "--source expert", "plugin": "a --source module:factory",
               "replay": "a --source lerobot:DIR",
               "remote": "a --source ws://HOST:PORT"}


@dataclass(frozen=True)
class SourceSettings:
    """Everything a source may be built from (the CLIs' switches).

    Attributes:
        spec: the ``--source`` setting (see the module).
        args: ``--source-arg`` settings for a plugin's factory.
        checkpoint: policy: its checkpoint (None: the shipped one).
        action_steps, refine_bins: policy decoding (``mmact_ctrl.policy_source.PolicyChunkSource``).
        expert_lead, bins, horizon, chunk_dt_s: the expert's chunks; ``chunk_dt_s`` is also a remote server's
            waypoint spacing (``--chunk-dt-s``), overriding its convention's.
        preset, obs_mapping, action_space, gripper, delta_from, action_rotation, action_scale, action_clip,
            image_rotation: remote: the server's convention (``mmact_ctrl.sources.presets``): a preset and the
            pieces that override it; None: not said (the server's metadata may say; nothing else does).
        given: the argparse dests the user gave (a switch that does not apply to the source is refused).
    """

    spec: str = "policy"
    args: dict = field(default_factory=dict)
    checkpoint: str | None = None
    action_steps: int = 1
    refine_bins: int | None = None
    expert_lead: str = "velocity"
    bins: int = 2048
    horizon: int = 16
    chunk_dt_s: float | None = None
    preset: str | None = None
    obs_mapping: str | None = None
    action_space: str | None = None
    gripper: str | None = None
    delta_from: str | None = None
    action_rotation: str | None = None
    action_scale: tuple[float, ...] | None = None
    action_clip: "tuple[float, float] | str | None" = None
    image_rotation: int | None = None
    given: frozenset[str] = frozenset()

    @property
    def kind(self) -> str:
        return source_kind(self.spec)

    def check(self) -> None:
        """One-line errors for switches that cannot mean anything with this source."""
        kind = self.kind
        given = set(self.given) | ({"checkpoint"} if self.checkpoint is not None else set()) | (
            {"args"} if self.args else set())
        for dest, (flag, kinds) in ONLY_FOR.items():
            if dest in given and kind not in kinds:
                why = (" (a policy server decides its chunk length: the connect block shows it)"
                       if kind == "remote" and dest == "horizon" else "")
                raise ValueError(f"{flag} is for {' or '.join(_KIND_WORDS[k] for k in kinds)}; --source {self.spec} "
                                 f"does not read it{why}")
        if kind != "remote":
            said = [f for f in CONVENTION_FIELDS if getattr(self, f) is not None]
            if said:
                flags = ", ".join("--" + f.replace("_", "-") for f in said)
                raise ValueError(f"{flags}: for a --source ws://HOST:PORT (a policy server's convention); "
                                 f"--source {self.spec} declares its own")

    def convention_switches(self):
        """The convention's switches of a remote source (``mmact_ctrl.sources.presets.resolve``)."""
        from mmact_ctrl.sources.presets.resolve import ConventionSwitches

        return ConventionSwitches(dt_s=self.chunk_dt_s,
                                  **{c: getattr(self, f) for f, c in CONVENTION_FIELDS.items()})


def settings_from_args(args: argparse.Namespace) -> SourceSettings:
    """:class:`SourceSettings` from a CLI's parsed arguments (missing switches take their defaults; a switch left at
    None was not given)."""
    from mmact_ctrl.sources.loader import parse_source_args

    get = lambda name, default=None: getattr(args, name, default)  # noqa: E731
    given = frozenset(d for d in ("action_steps", "refine_bins", "expert_lead", "horizon", "chunk_dt_s")
                      if get(d) is not None)
    refine = get("refine_bins")
    return SourceSettings(spec=args.source, args=parse_source_args(get("source_arg")), checkpoint=get("checkpoint"),
                          action_steps=get("action_steps") or 1, refine_bins=None if refine == "auto" else refine,
                          expert_lead=get("expert_lead") or "velocity", bins=get("bins", 2048),
                          horizon=get("horizon") or 16, chunk_dt_s=get("chunk_dt_s"),
                          given=given, **{f: get(f) for f in CONVENTION_FIELDS})


def _remote(settings: SourceSettings):
    from mmact_ctrl.sources.remote import RemoteSource

    return RemoteSource(settings.spec, settings.convention_switches())


def build_source(settings: SourceSettings, world=None):
    """The source ``settings`` name. The expert reads the target workspace of ``world`` (its lead reflects at the
    walls); every other source is built before its world (:func:`scene_settings` says what world it wants)."""
    settings.check()
    kind = settings.kind
    if kind == "policy":
        from mmact_ctrl.policy_source import PolicyChunkSource

        return PolicyChunkSource(settings.checkpoint, action_steps=settings.action_steps,
                                 refine_bins=settings.refine_bins)
    if kind == "expert":
        from scenarios.world.factory import make_expert

        return make_expert(bins=settings.bins, horizon=settings.horizon, dt_s=settings.chunk_dt_s or 0.1,
                           lead=settings.expert_lead, world=world)
    if kind == "remote":
        return _remote(settings)
    if kind == "replay":
        from mmact_ctrl.sources.loader import wrap_source
        from mmact_ctrl.sources.replay import LeRobotReplay, parse_replay_spec

        root, episode = parse_replay_spec(settings.spec)
        return wrap_source(LeRobotReplay(root, episode), f"--source {settings.spec}")
    from mmact_ctrl.sources.loader import load_source

    return load_source(settings.spec, settings.args)


def scene_settings(source) -> dict:
    """``make_world`` settings of the scenes ``source`` wants: our policy's (its cameras, training plane, two balls),
    or what a foreign source declares (``camera_names``, ``image_size_px``, ``scene``); empty for the expert."""
    if hasattr(source, "policy") and hasattr(getattr(source, "policy"), "bundle"):
        from scenarios.world.factory import policy_scene

        return policy_scene(source)
    spec = SourceSpec.of(source)
    out: dict = {k: spec.scene[k] for k in ("plane_z_m", "n_objects") if k in spec.scene}
    if spec.camera_names:
        out["cameras"] = spec.camera_names
    if spec.image_size_px:
        out["image_size_px"] = spec.image_size_px
    return out


def close_source(source) -> None:
    """``source.close()`` when it has one (a remote source's connection)."""
    fn = getattr(source, "close", None)
    if callable(fn):
        fn()


def first_observation(world, seed: int, needs_image: bool, model=None):
    """The observation the first episode of ``seed`` starts with (the world is reset to it): what the connect check
    and the conformance probe send."""
    import numpy as np

    from controllers.robot_model import PandaModel
    from controllers.rotations import rotvec_from_rot
    from mmact_ctrl.chunk import Observation

    model = model if model is not None else PandaModel()
    world.reset(seed)
    state = world.state()
    pos, rot = model.fk(state.q_rad)
    rotvec = rotvec_from_rot(rot, model.fk(model.home_q_rad)[1])
    return Observation(t0_s=0.0, q_rad=state.q_rad.copy(), dq_rad_s=np.asarray(state.dq_rad_s, dtype=float).copy(),
                       ee_pos_m=pos, ee_rotvec_rad=rotvec, gripper_m=float(state.gripper_m),
                       target_pos_m=world.target_pos_m().copy(), image=world.render() if needs_image else None,
                       instruction=world.instruction)


def connect_check(source, world, seed: int, replan_hz: float | None, latency_s: float | None, latency_from: str):
    """For a policy server (a ``RemoteSource``): send it the first episode's first observation and return the
    :class:`~mmact_ctrl.sources.remote.connect.ConnectReport` (None for any other source). A server that fails on
    it, or a reply that does not fit the convention, raises ``ConnectError`` (one line) before any episode.
    ``latency_s``: the latency chunks become active after (None: the first call's round trip)."""
    from mmact_ctrl.sources.remote import RemoteSource
    from mmact_ctrl.sources.remote.connect import connect_report, first_call

    if not isinstance(source, RemoteSource):
        return None
    obs = first_observation(world, seed, source.needs_image, source.adapter.model)
    return connect_report(source, first_call(source, obs), replan_hz, latency_s, latency_from)
