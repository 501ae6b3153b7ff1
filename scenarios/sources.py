"""The one place that turns a ``--source`` setting into a chunk source and the scene it runs in.

``--source`` takes

- ``policy``: the shipped unified-token policy (``--checkpoint`` for another);
- ``expert``: the scripted expert (``--expert-lead``, ``--bins``, ``--horizon``, ``--chunk-dt-s``);
- ``module.path:factory`` or ``path/to/file.py:factory``: any callable returning a chunk source, called with the
  ``--source-arg key=value`` settings (``mmact_ctrl.sources.loader``);
- ``ws://HOST:PORT``: a policy server speaking openpi's protocol (``mmact_ctrl.sources.openpi``), with
  ``--obs-mapping`` (which observation keys it reads) and ``--action-space`` / ``--gripper`` (what its actions are)
  unless the server declares them itself, as ``python -m scenarios.serve`` does.

The moving_target, sweep, faults and serve commands all build their sources here, so a source from anywhere gets the
same study, the same safety checks and the same report.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

#: the sources built in by name
BUILTIN_SOURCES: tuple[str, ...] = ("policy", "expert")


def source_kind(spec: str) -> str:
    """``policy``, ``expert``, ``remote`` (a ``ws://`` URL) or ``plugin`` (``module:factory``)."""
    from mmact_ctrl.sources.loader import is_plugin_spec

    if spec in BUILTIN_SOURCES:
        return spec
    if spec.startswith(("ws://", "wss://")):
        return "remote"
    if is_plugin_spec(spec):
        return "plugin"
    raise ValueError(f"--source {spec!r} is none of policy, expert, module.path:factory, file.py:factory, ws://HOST:PORT")


def source_spec_arg(text: str) -> str:
    """argparse ``type`` of ``--source``: the setting if it has one of the accepted forms (one-line error if not)."""
    try:
        source_kind(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


@dataclass(frozen=True)
class SourceSettings:
    """Everything a source may be built from (the CLIs' switches).

    Attributes:
        spec: the ``--source`` setting (see the module).
        args: ``--source-arg`` settings for a plugin's factory.
        checkpoint: policy: its checkpoint (None: the shipped one).
        action_steps, refine_bins: policy decoding (``mmact_ctrl.policy_source.PolicyChunkSource``).
        expert_lead, bins, horizon, chunk_dt_s: the expert's chunks; ``chunk_dt_s`` is also a remote source's
            waypoint spacing when the server does not declare it (None: 0.1 s).
        obs_mapping: remote: a preset (``mmact``, ``libero``, ``droid``) or a JSON mapping file (None: what the
            server declares, else ``mmact``).
        action_space, gripper: remote: what the server's actions are (None: what it declares, else ours).
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
    obs_mapping: str | None = None
    action_space: str | None = None
    gripper: str | None = None

    @property
    def kind(self) -> str:
        return source_kind(self.spec)

    def check(self) -> None:
        """One-line errors for switches that cannot mean anything with this source."""
        kind = self.kind
        if self.checkpoint is not None and kind != "policy":
            raise ValueError(f"--checkpoint is for --source policy; --source {self.spec} does not read it")
        if self.args and kind != "plugin":
            raise ValueError(f"--source-arg is for a --source module:factory; --source {self.spec} takes none")
        if kind != "remote" and (self.obs_mapping or self.action_space or self.gripper):
            raise ValueError(f"--obs-mapping, --action-space and --gripper are for a --source ws://HOST:PORT; "
                             f"--source {self.spec} declares its own")


def settings_from_args(args: argparse.Namespace) -> SourceSettings:
    """:class:`SourceSettings` from a CLI's parsed arguments (missing switches take their defaults)."""
    from mmact_ctrl.sources.loader import parse_source_args

    get = lambda name, default=None: getattr(args, name, default)  # noqa: E731
    return SourceSettings(spec=args.source, args=parse_source_args(get("source_arg")), checkpoint=get("checkpoint"),
                          action_steps=get("action_steps", 1), refine_bins=get("refine_bins"),
                          expert_lead=get("expert_lead", "velocity"), bins=get("bins", 2048), horizon=get("horizon", 16),
                          chunk_dt_s=get("chunk_dt_s"), obs_mapping=get("obs_mapping"),
                          action_space=get("action_space"), gripper=get("gripper"))


def _remote(settings: SourceSettings):
    from mmact_ctrl.sources.action_space import ActionSpace
    from mmact_ctrl.sources.openpi import RemoteSource

    space = None
    if settings.action_space or settings.gripper or settings.chunk_dt_s:
        space = ActionSpace(kind=settings.action_space or "tcp_pose", gripper=settings.gripper or "width_m",
                            dt_s=settings.chunk_dt_s or 0.1)
    return RemoteSource(settings.spec, mapping=settings.obs_mapping, action_space=space)


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
    from mmact_ctrl.sources.loader import load_source

    return load_source(settings.spec, settings.args)


def scene_settings(source) -> dict:
    """``make_world`` settings of the scenes ``source`` wants: our policy's (its cameras, training plane, two balls),
    or what a foreign source declares (``camera_names``, ``image_size_px``, ``scene``); empty for the expert."""
    if hasattr(source, "policy") and hasattr(getattr(source, "policy"), "bundle"):
        from scenarios.world.factory import policy_scene

        return policy_scene(source)
    out: dict = {}
    scene = getattr(source, "scene", None) or {}
    for key in ("plane_z_m", "n_objects"):
        if key in scene:
            out[key] = scene[key]
    cameras = getattr(source, "camera_names", None)
    if cameras:
        out["cameras"] = tuple(cameras)
    size = getattr(source, "image_size_px", None)
    if size:
        out["image_size_px"] = int(size)
    return out


def close_source(source) -> None:
    """``source.close()`` when it has one (a remote source's connection)."""
    fn = getattr(source, "close", None)
    if callable(fn):
        fn()
