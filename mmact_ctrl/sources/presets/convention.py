"""A convention: everything a policy's training fixed about what it reads and what it answers, as one frozen value.

A :class:`Convention` bundles the observation keys (which camera fills which key, at what size and orientation; the
state layout and dtype; the prompt), the action space (kind, ``delta_from``, rotation, per-dimension scale, clip,
gripper convention, waypoint spacing) and the chunk length its models emit. The built-in presets (``libero``,
``droid``, ``mmact``) are one file each in this package, with the code they were read from cited; a user defines
one in a JSON file (:func:`convention_from_dict`)::

    {
      "name": "my_robot",                       # default: the file name
      "based_on": "libero",                     # optional: start from a preset, override what follows
      "observation": {...},                     # an observation mapping (mmact_ctrl.sources.remote.mapping schema)
      "action": {"kind": "tcp_delta", "gripper": "sign", "control_hz": 20,   # or "dt_s": 0.05
                 "delta_from": "previous", "rotation": "nominal",
                 "scale": [0.05, 0.05, 0.05, 0.5, 0.5, 0.5], "clip": [-1, 1]},
      "horizon": 10,                            # the chunk length its models emit (null: any)
      "sources": ["where each value was read"]
    }
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

from mmact_ctrl.sources.action_space import ActionSpace
from mmact_ctrl.sources.remote.mapping import KeyMapping, MmactMapping, ObsMapping


@dataclass(frozen=True)
class Convention:
    """What a policy reads and answers.

    Attributes:
        name: how reports and errors name it.
        mapping: the observation keys (``KeyMapping``, or ``MmactMapping``: ours, which only a server of ours reads).
        action: the action space of its replies.
        horizon: the chunk length its models emit (None: any; a reply of another length is noted, not refused).
        state_rotation: how an orientation in its state is written (for the connect block), "" when it has none.
        sources: where each value was read (files of the anchors' code, with their commits).
    """

    name: str
    mapping: ObsMapping
    action: ActionSpace
    horizon: int | None = None
    state_rotation: str = ""
    sources: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"a convention needs a name, got {self.name!r}")
        if not isinstance(self.mapping, (KeyMapping, MmactMapping)):
            raise ValueError(f"convention {self.name!r}: mapping must be a KeyMapping or MmactMapping, got "
                             f"{type(self.mapping).__name__}")
        if not isinstance(self.action, ActionSpace):
            raise ValueError(f"convention {self.name!r}: action must be an ActionSpace, got {type(self.action).__name__}")
        if self.horizon is not None and not (isinstance(self.horizon, int) and self.horizon >= 1):
            raise ValueError(f"convention {self.name!r}: horizon must be an integer >= 1 or null, got {self.horizon!r}")
        object.__setattr__(self, "sources", tuple(self.sources))

    @property
    def chunk_s(self) -> float | None:
        """How long one chunk of :attr:`horizon` waypoints lasts, s (None without a horizon)."""
        return None if self.horizon is None else self.horizon * float(self.action.dt_s)

    def to_dict(self) -> dict:
        """The JSON form (a user preset file's schema; an ``mmact`` mapping is written by name)."""
        mapping = self.mapping.to_dict() if isinstance(self.mapping, KeyMapping) else "mmact"
        return {"name": self.name, "observation": mapping, "action": self.action.to_dict(), "horizon": self.horizon,
                "state_rotation": self.state_rotation, "sources": list(self.sources)}


_TOP = {"name", "based_on", "observation", "action", "horizon", "state_rotation", "sources"}


def _action(d: dict, base: ActionSpace | None, where: str) -> ActionSpace:
    if not isinstance(d, dict):
        raise ValueError(f"{where}: action must be an object, got {d!r}")
    d = dict(d)
    if "control_hz" in d:
        hz = d.pop("control_hz")
        if "dt_s" in d:
            raise ValueError(f"{where}: give the action's dt_s or its control_hz, not both")
        if not isinstance(hz, (int, float)) or not hz > 0:
            raise ValueError(f"{where}: control_hz must be a number > 0, got {hz!r}")
        d["dt_s"] = 1.0 / float(hz)
    merged = {**(base.to_dict() if base is not None else {}), **d}
    try:
        return ActionSpace.from_dict(merged)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def convention_from_dict(d: dict, name: str, presets: dict[str, Convention]) -> Convention:
    """A convention from its JSON form (``presets``: the built-ins a ``based_on`` may name); raises ``ValueError``
    naming the bad field."""
    where = f"preset {name!r}"
    if not isinstance(d, dict):
        raise ValueError(f"{where} must be a JSON object, got {type(d).__name__}")
    unknown = sorted(set(d) - _TOP)
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {unknown}; expected some of {sorted(_TOP)}")
    name = str(d.get("name", name))
    base = None
    if d.get("based_on") is not None:
        base = presets.get(d["based_on"])
        if base is None:
            raise ValueError(f"{where}: based_on {d['based_on']!r} is not a preset ({', '.join(presets)})")
    if "observation" in d:
        obs = d["observation"]
        mapping = MmactMapping() if obs == "mmact" else KeyMapping.from_dict(obs, name=name)
    elif base is not None:
        mapping = base.mapping
    else:
        raise ValueError(f"{where}: needs an observation mapping (or based_on a preset)")
    if "action" not in d and base is None:
        raise ValueError(f"{where}: needs an action space (or based_on a preset)")
    action = _action(d.get("action", {}), base.action if base is not None else None, where)
    horizon = d.get("horizon", base.horizon if base is not None else None)
    sources = tuple(d.get("sources") or ()) + ((f"based on the {base.name} preset",) if base is not None else ())
    return Convention(name=name, mapping=mapping, action=action, horizon=horizon,
                      state_rotation=str(d.get("state_rotation", base.state_rotation if base is not None else "")),
                      sources=sources)


def read_convention_file(path: Path, presets: dict[str, Convention]) -> Convention:
    """The convention a JSON file defines (raises ``ValueError`` naming the file)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"preset file {str(path)!r} is not readable JSON: {exc}") from None
    return convention_from_dict(data, Path(path).stem, presets)


def with_scene_cameras(convention: Convention, scene_cameras: tuple[str, ...]) -> Convention:
    """``convention`` with its key mapping told which cameras the scene has (others are black frames)."""
    if isinstance(convention.mapping, KeyMapping):
        return replace(convention, mapping=replace(convention.mapping, scene_cameras=tuple(scene_cameras)))
    return convention
