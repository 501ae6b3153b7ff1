"""Which observation keys carry the images, the state and the prompt: named mappings from our ``Observation`` to
the observation dict a policy server reads.

Presets (:data:`PRESETS`, :func:`load_mapping`):

``mmact``   our own keys, carrying everything an ``Observation`` holds, so that our server rebuilds the exact
            ``Observation`` (:meth:`MmactMapping.decode`) and a served source of ours behaves bit-identically:
            ``mmact/t0_s``, ``mmact/q_rad``, ``mmact/dq_rad_s``, ``mmact/ee_pos_m``, ``mmact/ee_rotvec_rad``,
            ``mmact/gripper_m``, ``mmact/target_pos_m``, ``mmact/target_prev_pos_m`` (absent when None),
            ``mmact/frame_gap_s``, ``mmact/image/<camera>`` and ``mmact/prev_image/<camera>`` (H, W, 3) uint8 per
            camera as rendered (absent when None), ``prompt`` (the instruction);
``libero``, ``droid``  the observation keys of those conventions (``mmact_ctrl.sources.presets``: each preset's file
            says what its keys hold and where that was read).

A user mapping is a JSON file (:func:`load_mapping` with its path) with this schema (every field but ``images`` /
``state`` optional; unknown fields are refused)::

    {
      "name": "my_policy",                 # default: the file name without .json
      "images": [                          # one entry per image key
        {"key": "observation/image",       # the key in the observation dict
         "camera": "front",                # a scene camera (front, top, side), or null: a black frame
         "size_px": 224,                   # the side of a square frame, or [height, width]
         "previous": false,                # true: the frame prev_frame_gap_s before the observation
         "rotate_deg": 0}                  # 0: as rendered (ours are upright); 180: turned upside down
      ],
      "state": [                           # one entry per state key: a float vector of the named parts
        {"key": "observation/state",
         "parts": ["ee_pos_m", "ee_axis_angle_rad", "gripper_fingers_m"],
         "dtype": "float32"}               # default float64
      ],
      "prompt_key": "prompt",              # null: no prompt is sent
      "prompt": null,                      # a fixed text instead of the scene's instruction
      "prev_frame_gap_s": 0.0              # > 0 when an image has "previous": true, s
    }

State parts (:data:`STATE_PARTS`, with their sizes): ``t0_s`` (1, s), ``q_rad`` (7), ``dq_rad_s`` (7), ``ee_pos_m``
(3, world frame), ``ee_rotvec_rad`` (3, ours: relative to the nominal grasp), ``ee_axis_angle_rad`` (3, the TCP
orientation as a world-frame axis-angle, continuous: the quaternion in the nominal grasp's hemisphere, angle in
[0, 2 pi] as robosuite's ``quat2axisangle``, :func:`controllers.rotations.axis_angle_in_hemisphere`), ``gripper_m``
(1, opening), ``gripper_fingers_m`` (2, +w/2 and -w/2), ``gripper_open_1`` (1, 1 = open), ``gripper_close_1`` (1,
1 = closed), ``target_pos_m`` (3), ``target_prev_pos_m`` (3, the current position before there is an earlier frame),
``frame_gap_s`` (1).

**Privileged parts** (:data:`PRIVILEGED_PARTS`: the true target, which a simulator knows and no real robot does):
a key mapping sends them only as ``mmact/<part>`` keys listed in ``KeyMapping.privileged``, which the client fills
only for a server of ours that asks for them in its metadata (``mmact_ctrl.sources.presets.resolve``), or when the
user put them in a mapping file or chose the ``mmact`` mapping; the connect block names them.

A mapping declares the scene cameras it needs (``camera_names``: the world must render these, in that order) and the
size to render them at (``image_size_px``). A camera the scene does not have (:data:`SCENE_CAMERAS`) fills its key
with a black frame, and ``missing_cameras`` says which. A frame rendered at another size is resized (bilinear).
"""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from mmact_ctrl.sources.remote.key_mapping import KeyMapping
from mmact_ctrl.sources.remote.keys import (GRIPPER_MAX_M, KNOWN_ACTIONS_KEY, N_CLIPPED_KEY, PRIVILEGED_PARTS,  # noqa: F401
                                            PROMPT_KEY, SCENE_CAMERAS, STATE_PARTS, TOKENS_KEY, ImageKey, StateKey,
                                            resize_bilinear, state_part)
from mmact_ctrl.sources.remote.mmact_mapping import MMACT_FIELDS, MmactMapping  # noqa: F401

__all__ = ["GRIPPER_MAX_M", "KNOWN_ACTIONS_KEY", "MMACT_FIELDS", "N_CLIPPED_KEY", "PRESETS", "PRIVILEGED_PARTS",
           "PROMPT_KEY", "SCENE_CAMERAS", "STATE_PARTS", "TOKENS_KEY", "ImageKey", "KeyMapping", "MmactMapping",
           "ObsMapping", "StateKey", "load_mapping", "resize_bilinear", "state_part"]

ObsMapping = KeyMapping | MmactMapping

#: the named mappings: each preset's (``mmact_ctrl.sources.presets``)
PRESETS: tuple[str, ...] = ("mmact", "libero", "droid")


def load_mapping(spec: "str | Path | ObsMapping", scene_cameras: tuple[str, ...] = SCENE_CAMERAS) -> ObsMapping:
    """A preset by name (:data:`PRESETS`), a user mapping by JSON file path, or ``spec`` itself when it is already
    a mapping (raises ``ValueError`` naming the bad name, path or field)."""
    if isinstance(spec, (KeyMapping, MmactMapping)):
        return replace(spec, scene_cameras=tuple(scene_cameras)) if isinstance(spec, KeyMapping) else spec
    text = str(spec)
    if text == "mmact":
        return MmactMapping()
    if text in PRESETS:
        from mmact_ctrl.sources.presets import PRESETS as CONVENTIONS

        return replace(CONVENTIONS[text].mapping, scene_cameras=tuple(scene_cameras))
    path = Path(text)
    if not path.is_file():
        raise ValueError(f"unknown observation mapping {text!r}: give a preset ({', '.join(PRESETS)}) or the path of a "
                         "JSON mapping file")
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"observation mapping file {text!r} is not readable JSON: {exc}") from None
    return KeyMapping.from_dict(data, name=path.stem, scene_cameras=tuple(scene_cameras))
