"""Any chunk source of ours as an openpi policy (``infer(obs: dict) -> dict``), with the metadata our client reads.

The observation arrives in the ``mmact`` mapping (:class:`~mmact_ctrl.sources.remote.mapping.MmactMapping`), is
rebuilt into the exact ``Observation`` and planned by the source; the reply holds

``actions``          the chunk's waypoints (H, 7) float64 in our task space (TCP position m, rotation vector
                     relative to the nominal grasp rad, gripper opening m);
``policy_timing``    ``{"infer_ms"}``: the source's ``plan`` (or ``plan_inpaint``) call, ms;
``mmact/tokens``     the action tokens (H, 7) int64 the waypoints came from (when the source quantizes);
``mmact/n_clipped``  actions the source clipped to its bounds.

An inpainting request carries ``mmact/known_actions`` (n, 7): the source's ``plan_inpaint`` is called with it.

The metadata (:func:`source_metadata`; openpi allows any dict, ours is under ``"mmact"``)::

    {"mmact": {"version": 1,
               "source": "ScriptedExpert",              # how the source names itself
               "obs_mapping": "mmact",                  # the observation keys the server reads
               "action_space": {...},                   # ActionSpace.to_dict(): tcp_pose, width_m, dt_s = chunk_dt_s
               "needs_image": false,
               "camera_names": ["front"],               # the cameras Observation.image holds, in order
               "image_size_px": 96,                     # the side to render them at (null: the world's default)
               "prev_frame_gap_s": 0.0,                 # > 0: the earlier frames too
               "chunk_dt_s": 0.1,
               "capabilities": ["inpaint"],             # mmact_ctrl.sources.contract.CAPABILITIES it provides
               "action_token_range": [lo, hi],          # half-open, of mmact/tokens (null: no tokens)
               "scene": {"plane_z_m": 0.1, "n_objects": 2}}}   # make_world settings it was made for (or null)
"""

from __future__ import annotations

import time

import numpy as np

from mmact_ctrl.chunk import ActionChunk
from mmact_ctrl.sources.action_space import ActionSpace
from mmact_ctrl.sources.contract import source_name
from mmact_ctrl.sources.spec import SourceSpec
from mmact_ctrl.sources.remote.mapping import KNOWN_ACTIONS_KEY, N_CLIPPED_KEY, TOKENS_KEY, MmactMapping

#: the version of our metadata extension
METADATA_VERSION = 1


def _float_or_none(value) -> float | None:
    return None if value is None else float(value)


def source_metadata(source, scene: dict | None = None) -> dict:
    """The metadata frame of ``source`` served by :class:`SourcePolicy` (``scene``: its ``make_world`` settings,
    default what the source declares)."""
    spec = SourceSpec.of(source)
    dt = spec.chunk_dt_s
    if not (isinstance(dt, (int, float)) and dt > 0):
        raise ValueError(f"source {spec.name!r} has no chunk_dt_s > 0 (got {dt!r}): a client cannot time its waypoints")
    dt = float(dt)
    cams = spec.camera_names or (("front",) if spec.needs_image else ())
    tok = spec.action_token_range
    scene = scene if scene is not None else (spec.scene or None)
    return {"mmact": {
        "version": METADATA_VERSION,
        "source": spec.name,
        "obs_mapping": "mmact",
        "action_space": ActionSpace(dt_s=dt).to_dict(),
        "needs_image": spec.needs_image,
        "camera_names": list(cams),
        "image_size_px": spec.image_size_px,
        "prev_frame_gap_s": spec.prev_frame_gap_s,
        "chunk_dt_s": dt,
        "capabilities": sorted(spec.capabilities),
        "action_token_range": None if tok is None else [int(tok[0]), int(tok[1])],
        "scene": None if scene is None else {k: (v if isinstance(v, (str, bool, int)) else _float_or_none(v))
                                             for k, v in dict(scene).items() if k in ("plane_z_m", "n_objects")},
    }}


class SourcePolicy:
    """``source`` (a ``ChunkSource`` of ours) as an openpi policy.

    Args:
        source: the chunk source (its ``plan`` returns our task-space ``ActionChunk``).
        scene: the ``make_world`` settings it was made for (``plane_z_m``, ``n_objects``), for the metadata.
        infer_delay_ms: each answer takes at least this long (a stand-in for a slower model), ms.
    """

    def __init__(self, source, scene: dict | None = None, infer_delay_ms: float = 0.0) -> None:
        self.source = source
        self.infer_delay_s = float(infer_delay_ms) / 1e3
        self.metadata = source_metadata(source, scene)
        m = self.metadata["mmact"]
        self.mapping = MmactMapping(camera_names=tuple(m["camera_names"]), image_size_px=m["image_size_px"],
                                    prev_frame_gap_s=m["prev_frame_gap_s"], needs_image=m["needs_image"])
        self.can_inpaint = "inpaint" in m["capabilities"]
        self.chunk_dt_s = float(m["chunk_dt_s"])

    @property
    def name(self) -> str:
        return source_name(self.source)

    def reset(self) -> None:
        fn = getattr(self.source, "reset", None)
        if callable(fn):
            fn()

    def infer(self, obs: dict) -> dict:
        """Plan one chunk from an ``mmact``-mapped observation dict (raises ``ValueError`` naming a bad key)."""
        observation = self.mapping.decode(obs)
        known = obs.get(KNOWN_ACTIONS_KEY)
        t0 = time.perf_counter()
        if known is not None:
            if not self.can_inpaint:
                raise ValueError(f"source {self.name!r} cannot inpaint, but the request holds {KNOWN_ACTIONS_KEY!r}")
            known = np.array(known, dtype=np.float64).reshape(-1, 7)
            chunk = self.source.plan_inpaint(observation, known)
        else:
            chunk = self.source.plan(observation)
        wait = self.infer_delay_s - (time.perf_counter() - t0)
        if wait > 0:
            time.sleep(wait)
        infer_ms = (time.perf_counter() - t0) * 1e3
        if not isinstance(chunk, ActionChunk):
            raise TypeError(f"source {self.name!r} returned {type(chunk).__name__}, not an ActionChunk")
        if abs(float(chunk.dt_s) - self.chunk_dt_s) > 1e-12:
            raise ValueError(f"source {self.name!r} declares chunk_dt_s {self.chunk_dt_s:g} s but returned a chunk "
                             f"with dt {chunk.dt_s:g} s: the client times waypoints by the declared spacing")
        reply = {"actions": np.ascontiguousarray(chunk.waypoints, dtype=np.float64),
                 "policy_timing": {"infer_ms": infer_ms},
                 N_CLIPPED_KEY: int(chunk.n_clipped)}
        if chunk.tokens is not None:
            reply[TOKENS_KEY] = np.ascontiguousarray(chunk.tokens, dtype=np.int64)
        return reply
