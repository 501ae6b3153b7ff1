"""A chunk source behind a policy server speaking openpi's protocol (``--source ws://HOST:PORT``).

:class:`RemoteSource` maps each ``Observation`` to the server's observation dict (an observation mapping,
:mod:`~mmact_ctrl.sources.openpi.mapping`), calls the server (:class:`~mmact_ctrl.sources.openpi.client.PolicyClient`)
and turns the reply's ``"actions"`` (H, D) of the declared :class:`~mmact_ctrl.sources.action_space.ActionSpace` into
our task-space ``ActionChunk``, whose ``info`` holds

``round_trip_ms``    the call's round trip (send to reply decoded), ms;
``server_infer_ms``  the reply's ``server_timing.infer_ms`` (None when the server does not say);
``policy_infer_ms``  the reply's ``policy_timing.infer_ms`` (None when the policy does not say).

A server of ours (``python -m scenarios.serve``) declares everything in its metadata (``"mmact"``, see
:mod:`~mmact_ctrl.sources.openpi.serving`): the source then configures itself from it (the ``mmact`` mapping with
the server source's cameras, its action space, capabilities, token range and scene). A foreign server declares
nothing of this: the caller gives the mapping and the action space.

Every failure of a call raises (the loop counts it as a rejected chunk and keeps the previous one running): the
wire's own errors (:class:`~mmact_ctrl.sources.openpi.client.WireError`: timeout, lost connection, error frame) and
``ValueError`` for a reply without ``actions``, of the wrong shape, or with NaN (naming the shape or the waypoint).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.sources.action_space import ActionAdapter, ActionSpace
from mmact_ctrl.sources.contract import CAPABILITIES, SourceError
from mmact_ctrl.sources.openpi.client import ClientConfig, PolicyClient
from mmact_ctrl.sources.openpi.mapping import (KNOWN_ACTIONS_KEY, N_CLIPPED_KEY, SCENE_CAMERAS, TOKENS_KEY,
                                               MmactMapping, ObsMapping, load_mapping)


def _mmact_metadata(metadata: dict) -> dict | None:
    meta = metadata.get("mmact") if isinstance(metadata, dict) else None
    return meta if isinstance(meta, dict) else None


class RemoteSource:
    """A ``ChunkSource`` over a policy server.

    Args:
        url: ``ws://host:port``.
        mapping: the observation mapping: a preset name (``mmact``, ``libero``, ``droid``), a JSON file path, or a
            mapping object; None: from the server's metadata (a server of ours), else an error.
        action_space: the server's action space (``ActionSpace`` or its dict); None: from the server's metadata.
        config: the client's timeouts and retries.
        model: the robot model for joint-space actions (None: the Panda's).
        scene_cameras: the cameras the scene has (image keys of other cameras get black frames).

    Raises:
        ServerUnreachable: the server cannot be reached (a ``SourceError``: one line naming the URL).
        SourceError: the mapping or the action space is missing, contradicts the server's, or is malformed.
    """

    def __init__(self, url: str, mapping: "str | Path | ObsMapping | None" = None,
                 action_space: "ActionSpace | dict | None" = None, config: ClientConfig = ClientConfig(), model=None,
                 scene_cameras: tuple[str, ...] = SCENE_CAMERAS) -> None:
        self.client = PolicyClient(url, config)
        try:
            self._configure(mapping, action_space, model, tuple(scene_cameras))
        except Exception:
            self.client.close()
            raise

    # ---- configuration ---------------------------------------------------------------------------------------
    def _configure(self, mapping, action_space, model, scene_cameras) -> None:
        url = self.name
        if isinstance(action_space, dict):
            action_space = _space_from_dict(action_space, f"the action space given for {url}")
        self._meta = _mmact_metadata(self.client.metadata)
        self.action_token_range: tuple[int, int] | None = None
        self.declared_capabilities: frozenset[str] = frozenset()
        if self._meta is not None:
            mapping, action_space = self._from_metadata(mapping, action_space)
        else:
            if mapping is None:
                raise SourceError(f"the policy server at {url} does not declare its observation keys (no 'mmact' "
                                  "metadata: a foreign server): give an observation mapping (mmact, libero, droid, "
                                  "or a JSON mapping file)")
            if action_space is None:
                raise SourceError(f"the policy server at {url} does not declare its action space (a foreign server): "
                                  "give one (kind, gripper convention, dt_s)")
        if not isinstance(action_space, ActionSpace):
            raise SourceError(f"the action space for {url} must be an ActionSpace or its dict, got {action_space!r}")
        try:
            self.mapping = load_mapping(mapping, scene_cameras)
        except ValueError as exc:
            raise SourceError(str(exc)) from None
        self.space = action_space
        self.adapter = ActionAdapter(action_space, model)
        self._rot_nominal = self.adapter.model.fk(self.adapter.model.home_q_rad)[1]

    def _from_metadata(self, mapping, action_space):
        meta, url = self._meta, self.name
        declared = _space_from_dict(meta.get("action_space"), f"the action space the server at {url} declares")
        if action_space is not None and action_space != declared:
            raise SourceError(f"the policy server at {url} declares the action space {declared.describe()}, not "
                              f"{action_space.describe()}: leave the action space out")
        name = meta.get("obs_mapping", "mmact")
        if name != "mmact":
            raise SourceError(f"the policy server at {url} reads the observation mapping {name!r}, which this client "
                              "does not know")
        if mapping is not None and not (mapping == "mmact" or isinstance(mapping, MmactMapping)):
            raise SourceError(f"the policy server at {url} is a server of ours and reads the 'mmact' observation keys: "
                              f"the mapping {str(getattr(mapping, 'name', mapping))!r} does not apply (leave it out)")
        try:
            cams = tuple(str(c) for c in meta.get("camera_names") or ())
            size = meta.get("image_size_px")
            mapping = MmactMapping(camera_names=cams, image_size_px=None if size is None else int(size),
                                   prev_frame_gap_s=float(meta.get("prev_frame_gap_s") or 0.0),
                                   needs_image=bool(meta.get("needs_image", True)))
            tok = meta.get("action_token_range")
            self.action_token_range = None if tok is None else (int(tok[0]), int(tok[1]))
        except (TypeError, ValueError, IndexError) as exc:
            raise SourceError(f"the policy server at {url} sent malformed 'mmact' metadata: {exc}") from None
        caps = meta.get("capabilities") or ()
        self.declared_capabilities = frozenset(str(c) for c in caps if str(c) in CAPABILITIES)
        if isinstance(meta.get("scene"), dict):
            self.scene = dict(meta["scene"])
        return mapping, declared

    # ---- what the loop and the CLIs read ----------------------------------------------------------------------
    @property
    def name(self) -> str:
        return self.client.url

    @property
    def metadata(self) -> dict:
        return self.client.metadata

    @property
    def needs_image(self) -> bool:
        return self.mapping.needs_image

    @property
    def camera_names(self) -> tuple[str, ...]:
        return self.mapping.camera_names

    @property
    def image_size_px(self) -> int | None:
        return self.mapping.image_size_px

    @property
    def prev_frame_gap_s(self) -> float:
        return float(self.mapping.prev_frame_gap_s)

    @property
    def chunk_dt_s(self) -> float:
        return float(self.space.dt_s)

    @property
    def missing_cameras(self) -> tuple[str, ...]:
        """Cameras the mapping names that the scene lacks (their keys are black frames)."""
        return self.mapping.missing_cameras

    def describe(self) -> str:
        """One line: the URL, who declared what, the mapping and the action space."""
        who = (f"server of ours ({self._meta.get('source', '?')})" if self._meta is not None else "foreign server")
        caps = ", ".join(sorted(self.declared_capabilities)) or "none"
        return f"{self.name}: {who}; {self.mapping.describe()}; actions {self.space.describe()}; capabilities {caps}"

    # ---- the contract -----------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Nothing to reset remotely (openpi's protocol has no reset message); the connection stays."""

    def close(self) -> None:
        self.client.close()

    def plan(self, observation: Observation) -> ActionChunk:
        return self._request(observation, None)

    def plan_inpaint(self, observation: Observation, known: np.ndarray) -> ActionChunk:
        """Real-time chunking over the wire (our extension): ``known`` (n, 7) travels as ``mmact/known_actions``;
        only for a server that declares the ``inpaint`` capability."""
        if "inpaint" not in self.declared_capabilities:
            raise SourceError(f"the policy server at {self.name} does not declare the inpaint capability")
        return self._request(observation, np.ascontiguousarray(known, dtype=np.float64).reshape(-1, 7))

    def _request(self, observation: Observation, known: np.ndarray | None) -> ActionChunk:
        obs = self.mapping.encode(observation, self._rot_nominal)
        if known is not None:
            obs[KNOWN_ACTIONS_KEY] = known
        reply = self.client.infer(obs)
        self._check_same_server()
        call = self.client.calls[-1]
        if "actions" not in reply:
            raise ValueError(f"{self.name}: the reply has no 'actions' (keys: {sorted(map(str, reply))[:12]})")
        actions = np.asarray(reply["actions"])
        if actions.dtype.kind not in "biuf":
            raise ValueError(f"{self.name}: 'actions' must be numbers, got dtype {actions.dtype} shape {actions.shape}")
        tokens = reply.get(TOKENS_KEY) if self.action_token_range is not None else None
        info = {"round_trip_ms": call.round_trip_ms, "server_infer_ms": call.server_infer_ms,
                "policy_infer_ms": call.policy_infer_ms}
        try:
            chunk = self.adapter.to_chunk(actions, observation, tokens=tokens, info=info)
        except ValueError as exc:
            raise ValueError(f"{self.name}: {exc}") from None
        n_clipped = reply.get(N_CLIPPED_KEY)
        if isinstance(n_clipped, (int, np.integer)) and n_clipped > 0:
            chunk = replace(chunk, n_clipped=int(n_clipped))
        return chunk

    def _check_same_server(self) -> None:
        """After a reconnect the server must declare what it declared first (not a different source)."""
        if self._meta is None:
            return
        now = _mmact_metadata(self.client.metadata)
        if now is not self._meta and now != self._meta:
            raise SourceError(f"the policy server at {self.name} declares other metadata since it reconnected (a "
                              "different source?): its chunks are refused")


def _space_from_dict(d, what: str) -> ActionSpace:
    if not isinstance(d, dict):
        raise SourceError(f"{what} must be a dict of ActionSpace fields, got {d!r}")
    try:
        return ActionSpace.from_dict(d)
    except (TypeError, ValueError) as exc:
        raise SourceError(f"{what} is malformed: {exc}") from None
