"""How a client settles the convention of a policy server: the user's switches, the server's word, one answer.

Three voices, in this order of authority:

1. **The server's word** (its metadata frame, :func:`server_word`): a server of ours declares everything under
   ``"mmact"`` (``obs_mapping``, ``action_space``, ...); any server may name a preset (``"preset": "libero"``, or
   ``{"mmact": {"obs_mapping": "libero"}}``); openpi-style ``action_horizon`` is read as the chunk length; a server
   of ours may ask for the privileged target keys (``{"mmact": {"privileged": ["target_pos_m", ...]}}``).
2. **The user's switches** (:class:`ConventionSwitches`): ``--preset`` gives a whole convention, each piece's own
   switch (``--obs-mapping``, ``--action-space``, ``--gripper``, ``--delta-from``, ``--action-rotation``,
   ``--action-scale``, ``--action-clip``, ``--chunk-dt-s``, ``--image-rotation``) overrides that piece.
3. Nothing else: there is no default convention. A foreign server that declares none and a user who names none
   get one line naming ``--preset`` and the presets, before any episode.

Where the server declares a piece and a switch says otherwise, that is one line naming both (:class:`SourceError`);
a switch that does not apply to the settled action kind (``--delta-from`` for absolute poses, ``--action-rotation``
for anything but ``tcp_pose``, ``--image-rotation`` for our own ``mmact`` keys) is refused too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from mmact_ctrl.sources.action_space import GRIPPERS, KINDS, ActionSpace
from mmact_ctrl.sources.contract import SourceError
from mmact_ctrl.sources.remote.mapping import (PRIVILEGED_PARTS, SCENE_CAMERAS, KeyMapping, MmactMapping, ObsMapping,
                                               load_mapping)
from mmact_ctrl.sources.presets import PRESETS, Convention, load_preset
from mmact_ctrl.sources.presets.convention import with_scene_cameras

#: the switch that names each piece, as errors say it
FLAGS: dict[str, str] = {
    "preset": "--preset", "obs_mapping": "--obs-mapping", "kind": "--action-space", "gripper": "--gripper",
    "delta_from": "--delta-from", "rotation": "--action-rotation", "scale": "--action-scale", "clip": "--action-clip",
    "dt_s": "--chunk-dt-s", "image_rotation_deg": "--image-rotation",
}
#: the action pieces a switch can set, by ``ActionSpace`` field
ACTION_PIECES: tuple[str, ...] = ("kind", "gripper", "dt_s", "rotation", "delta_from", "scale", "clip")
#: what a foreign server must be told when no preset is named
REQUIRED_WITHOUT_PRESET: tuple[str, ...] = ("obs_mapping", "kind", "gripper", "dt_s")
#: the metadata keys read from any server (besides ours under "mmact")
METADATA_KEYS: tuple[str, ...] = ("preset", "action_horizon", "action_dim")
NO_CLIP = "none"


@dataclass(frozen=True)
class ConventionSwitches:
    """What the user said (None: not said). ``scale`` and ``clip`` as tuples; ``clip`` may be ``"none"`` (no
    clipping, overriding a preset's). ``obs_mapping`` and ``preset`` may also be objects (from Python)."""

    preset: "str | Convention | None" = None
    obs_mapping: "str | ObsMapping | None" = None
    kind: str | None = None
    gripper: str | None = None
    delta_from: str | None = None
    rotation: str | None = None
    scale: tuple[float, ...] | None = None
    clip: "tuple[float, float] | str | None" = None
    dt_s: float | None = None
    image_rotation_deg: int | None = None

    @classmethod
    def from_space(cls, space: ActionSpace, **kw) -> "ConventionSwitches":
        """Every action piece of ``space`` that applies to its kind said (a whole ``ActionSpace`` given from Python)."""
        skip = {"delta_from"} if space.kind not in ("tcp_delta", "joint_delta") else set()
        skip |= {"rotation"} if space.kind != "tcp_pose" else set()
        skip |= {p for p in ("scale", "clip") if getattr(space, p) is None}
        return cls(**{p: getattr(space, p) for p in ACTION_PIECES if p not in skip}, **kw)

    def given(self) -> tuple[str, ...]:
        """The pieces said, in :data:`FLAGS` order."""
        return tuple(k for k in FLAGS if getattr(self, k) is not None)

    def check(self) -> None:
        """One-line errors for values no convention can have."""
        if self.kind is not None and self.kind not in KINDS:
            raise SourceError(f"--action-space must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if self.gripper is not None and self.gripper not in GRIPPERS:
            raise SourceError(f"--gripper must be one of {', '.join(GRIPPERS)}, got {self.gripper!r}")
        if self.delta_from is not None and self.delta_from not in ("observation", "previous"):
            raise SourceError(f"--delta-from must be observation or previous, got {self.delta_from!r}")
        if self.rotation is not None and self.rotation not in ("nominal", "world"):
            raise SourceError(f"--action-rotation must be nominal or world, got {self.rotation!r}")
        if self.image_rotation_deg is not None and self.image_rotation_deg not in (0, 180):
            raise SourceError(f"--image-rotation must be 0 or 180, got {self.image_rotation_deg!r}")
        if self.dt_s is not None and not (isinstance(self.dt_s, (int, float)) and math.isfinite(self.dt_s)
                                          and self.dt_s > 0):
            raise SourceError(f"--chunk-dt-s must be a number of seconds > 0, got {self.dt_s!r}")


@dataclass(frozen=True)
class ServerWord:
    """What a server's metadata declares.

    Attributes:
        convention: the convention it declares (a preset it names, or ours in full), or None.
        declared: the pieces it declares (``obs_mapping`` and :data:`ACTION_PIECES` names).
        ours: it is a server of ours (it sent ``"mmact"`` metadata).
        action_horizon: the chunk length it says it answers (openpi's ``action_horizon``), or None.
        privileged: the privileged parts it asks for.
        scene: the ``make_world`` settings it was made for (ours), or None.
        source_name: how it names its source (ours), or None.
        extra_keys: other metadata keys it sent (shown, not read).
    """

    convention: Convention | None = None
    declared: tuple[str, ...] = ()
    ours: bool = False
    action_horizon: int | None = None
    privileged: tuple[str, ...] = ()
    scene: dict | None = None
    source_name: str | None = None
    extra_keys: tuple[str, ...] = ()


@dataclass(frozen=True)
class Resolved:
    """The settled convention and where each piece came from.

    Attributes:
        convention: what the client will send and read (its mapping with any privileged keys the server asked for).
        origin: piece -> who set it (``"preset libero"``, ``"server"``, ``"--delta-from"``, ...).
        word: what the server declared.
    """

    convention: Convention
    origin: dict = field(default_factory=dict)
    word: ServerWord = field(default_factory=ServerWord)

    @property
    def privileged_keys(self) -> tuple[str, ...]:
        return self.convention.mapping.privileged_keys


def _int_or_none(value, what: str, url: str) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or int(value) != value or value < 1:
        raise SourceError(f"the policy server at {url} sent {what} {value!r}, not an integer >= 1")
    return int(value)


def _ours(m: dict, url: str) -> Convention:
    """Our server's full declaration: the mmact keys with its cameras (or a preset's keys) and its action space."""
    try:
        space = ActionSpace.from_dict(m["action_space"])
        name = m.get("obs_mapping", "mmact")
        if name == "mmact":
            size = m.get("image_size_px")
            mapping = MmactMapping(camera_names=tuple(str(c) for c in m.get("camera_names") or ()),
                                   image_size_px=None if size is None else int(size),
                                   prev_frame_gap_s=float(m.get("prev_frame_gap_s") or 0.0),
                                   needs_image=bool(m.get("needs_image", True)))
        else:
            mapping = load_preset(name).mapping
    except (TypeError, ValueError, KeyError) as exc:
        raise SourceError(f"the policy server at {url} sent malformed 'mmact' metadata: {exc}") from None
    return Convention(name=f"{url} (declared)", mapping=mapping, action=space, horizon=None)


def server_word(metadata: dict, url: str) -> ServerWord:
    """What ``metadata`` declares (raises :class:`SourceError` for a malformed declaration or a preset it names that
    this client does not know)."""
    meta = metadata if isinstance(metadata, dict) else {}
    m = meta.get("mmact") if isinstance(meta.get("mmact"), dict) else None
    horizon = _int_or_none(meta.get("action_horizon"), "action_horizon", url)
    convention, declared = None, ()
    named = meta.get("preset")
    if m is not None and "action_space" in m:
        convention, declared = _ours(m, url), ("obs_mapping",) + ACTION_PIECES
    else:
        named = m.get("obs_mapping", named) if m is not None else named
        if named is not None:
            if not (isinstance(named, str) and named in PRESETS):
                raise SourceError(f"the policy server at {url} names the convention {named!r}, which this client does "
                                  f"not know (presets: {', '.join(PRESETS)})")
            convention, declared = PRESETS[named], ("obs_mapping",) + ACTION_PIECES
    privileged = tuple(str(p) for p in (m.get("privileged") or ())) if m is not None else ()
    bad = [p for p in privileged if p not in PRIVILEGED_PARTS]
    if bad:
        raise SourceError(f"the policy server at {url} asks for {bad}, which are not privileged parts "
                          f"({', '.join(PRIVILEGED_PARTS)})")
    scene = dict(m["scene"]) if m is not None and isinstance(m.get("scene"), dict) else None
    extra = tuple(sorted(str(k) for k in meta if k not in METADATA_KEYS and k != "mmact"))
    return ServerWord(convention, declared, m is not None, horizon, privileged, scene,
                      str(m.get("source")) if m is not None and m.get("source") else None, extra)


def _value(conv: Convention, piece: str):
    if piece == "obs_mapping":
        return conv.mapping
    if piece == "image_rotation_deg":
        rots = {k.rotate_deg for k in getattr(conv.mapping, "images", ()) if k.camera is not None}
        return rots.pop() if len(rots) == 1 else 0
    return getattr(conv.action, piece)


def _said(switches: ConventionSwitches, piece: str, scene_cameras: tuple[str, ...]):
    """The value of a piece as the user said it, in the convention's terms."""
    value = getattr(switches, piece)
    if piece == "obs_mapping":
        try:
            return load_mapping(value, scene_cameras)
        except ValueError as exc:
            raise SourceError(f"--obs-mapping: {exc}") from None
    if piece == "clip":
        return None if value == NO_CLIP else tuple(float(v) for v in value)
    if piece == "scale":
        return tuple(float(v) for v in value)
    return value


def _same(piece: str, a, b) -> bool:
    if piece == "obs_mapping" and isinstance(a, KeyMapping) and isinstance(b, KeyMapping):
        return replace(a, name="", privileged=()) == replace(b, name="", privileged=())
    if piece == "obs_mapping":
        return type(a) is type(b) and (isinstance(a, MmactMapping) or a == b)
    if piece == "dt_s":
        return abs(float(a) - float(b)) <= 1e-9
    if piece == "scale" and a is not None and b is not None:
        return tuple(a) == tuple(b) or (len(set(a)) == 1 and len(set(b)) == 1 and a[0] == b[0])
    return a == b


def _show(piece: str, value) -> str:
    if piece == "obs_mapping":
        return repr(getattr(value, "name", value))
    if piece == "clip":
        return NO_CLIP if value is None else f"{value[0]:g},{value[1]:g}"
    if piece == "scale":
        return "none" if value is None else ",".join(f"{v:g}" for v in value)
    if piece == "dt_s":
        return f"{float(value):g}"
    return str(value)


def _no_convention(url: str, given: tuple[str, ...]) -> SourceError:
    presets = ", ".join(PRESETS)
    if not given:
        return SourceError(f"the policy server at {url} does not declare its convention: give --preset "
                           f"({presets}, or a JSON preset file), or --obs-mapping with --action-space, --gripper and "
                           "--chunk-dt-s")
    missing = " ".join(FLAGS[p] for p in REQUIRED_WITHOUT_PRESET if p not in given)
    return SourceError(f"the policy server at {url} does not declare its convention and no --preset was given: "
                       f"{' '.join(FLAGS[p] for p in given)} also need{'s' if len(given) == 1 else ''} {missing} (or "
                       f"give --preset: {presets})")


def _base(word: ServerWord, switches: ConventionSwitches, url: str) -> tuple[Convention | None, str]:
    """The convention the pieces start from, and who named it."""
    mine = None
    if switches.preset is not None:
        try:
            mine = load_preset(switches.preset)
        except ValueError as exc:
            raise SourceError(f"--preset: {exc}") from None
    theirs = word.convention
    if mine is not None and theirs is not None:
        differ = [p for p in ("obs_mapping",) + ACTION_PIECES if not _same(p, _value(mine, p), _value(theirs, p))]
        if differ:
            p = differ[0]
            whose = "its metadata" if word.ours and theirs.name not in PRESETS else f"the {theirs.name} preset"
            raise SourceError(f"the policy server at {url} declares {FLAGS[p][2:]} {_show(p, _value(theirs, p))} "
                              f"({whose}); --preset {mine.name} says {_show(p, _value(mine, p))}: leave --preset out, or "
                              "serve the other convention")
    if mine is not None:
        return mine, f"--preset {mine.name}"
    if theirs is not None:
        return theirs, "server"
    return None, ""


def _apply(conv: Convention, piece: str, value) -> Convention:
    if piece == "obs_mapping":
        return replace(conv, mapping=value)
    if piece == "image_rotation_deg":
        if not isinstance(conv.mapping, KeyMapping):
            raise SourceError("--image-rotation applies to a key mapping (libero, droid, a JSON file), not to our own "
                              "mmact keys (frames travel as rendered)")
        images = tuple(replace(k, rotate_deg=value) for k in conv.mapping.images)
        return replace(conv, mapping=replace(conv.mapping, images=images))
    try:
        return replace(conv, action=replace(conv.action, **{piece: value}))
    except ValueError as exc:
        raise SourceError(f"{FLAGS[piece]}: {exc}") from None


def _from_pieces(switches: ConventionSwitches, url: str, scene_cameras: tuple[str, ...]) -> Convention:
    given = switches.given()
    if any(p not in given for p in REQUIRED_WITHOUT_PRESET):
        raise _no_convention(url, given)
    if switches.kind in ("tcp_delta", "joint_delta") and switches.delta_from is None:
        raise SourceError(f"--action-space {switches.kind} without a --preset needs --delta-from: observation (every row "
                          "a delta from the observed pose) or previous (rows are successive steps, as LIBERO's and "
                          "DROID's are)")
    if switches.kind == "tcp_pose" and switches.rotation is None:
        raise SourceError("--action-space tcp_pose without a --preset needs --action-rotation: world (an absolute "
                          "axis-angle, as LIBERO's state) or nominal (ours: relative to the hand pointing down)")
    mapping = _said(switches, "obs_mapping", scene_cameras)
    return Convention(name="custom", mapping=mapping,
                      action=ActionSpace(kind=switches.kind, gripper=switches.gripper, dt_s=float(switches.dt_s)),
                      horizon=None)


def _check_applies(conv: Convention, given: tuple[str, ...]) -> None:
    kind = conv.action.kind
    if "delta_from" in given and kind not in ("tcp_delta", "joint_delta"):
        raise SourceError(f"--delta-from applies to tcp_delta and joint_delta actions; the convention's actions are {kind}")
    if "rotation" in given and kind != "tcp_pose":
        raise SourceError(f"--action-rotation applies to tcp_pose actions; the convention's actions are {kind}")


def resolve(metadata: dict, switches: ConventionSwitches, url: str,
            scene_cameras: tuple[str, ...] = SCENE_CAMERAS) -> Resolved:
    """The convention to speak with the server at ``url`` (raises :class:`SourceError`, one line naming the switch,
    the server's word or the missing piece)."""
    switches.check()
    word = server_word(metadata, url)
    base, who = _base(word, switches, url)
    given = tuple(p for p in switches.given() if p != "preset")
    conv = base if base is not None else _from_pieces(switches, url, scene_cameras)
    origin = {p: (who if base is not None else FLAGS[p] if p in given else "default")
              for p in ("obs_mapping",) + ACTION_PIECES}
    origin["image_rotation_deg"] = who if base is not None else "default"
    for piece in given:
        value = _said(switches, piece, scene_cameras)
        if piece in word.declared and not _same(piece, value, _value(word.convention, piece)):
            raise SourceError(f"the policy server at {url} declares {FLAGS[piece][2:]} "
                              f"{_show(piece, _value(word.convention, piece))}; {FLAGS[piece]} {_show(piece, value)} "
                              f"contradicts it: leave {FLAGS[piece]} out")
        conv = _apply(conv, piece, value)
        origin[piece] = FLAGS[piece]
    _check_applies(conv, given)
    if word.action_horizon is not None:
        conv = replace(conv, horizon=word.action_horizon)
        origin["horizon"] = "server (action_horizon)"
    else:
        origin["horizon"] = who if base is not None and conv.horizon is not None else "not declared"
    conv = with_scene_cameras(conv, scene_cameras)
    if word.privileged:
        if not isinstance(conv.mapping, KeyMapping):
            pass  # the mmact keys carry the true target already
        else:
            conv = replace(conv, mapping=replace(conv.mapping, privileged=word.privileged))
    return Resolved(convention=conv, origin=origin, word=word)
