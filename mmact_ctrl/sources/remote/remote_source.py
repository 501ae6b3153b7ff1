"""A chunk source behind a policy server speaking openpi's protocol (``--source ws://HOST:PORT``).

:class:`RemoteSource` maps each ``Observation`` to the server's observation dict (an observation mapping,
:mod:`~mmact_ctrl.sources.remote.mapping`), calls the server (:class:`~mmact_ctrl.sources.openpi.client.PolicyClient`)
and turns the reply's ``"actions"`` (H, D) of the declared :class:`~mmact_ctrl.sources.action_space.ActionSpace` into
our task-space ``ActionChunk``, whose ``info`` holds

``round_trip_ms``    the call's round trip (send to reply decoded), ms;
``server_infer_ms``  the reply's ``server_timing.infer_ms`` (None when the server does not say);
``policy_infer_ms``  the reply's ``policy_timing.infer_ms`` (None when the policy does not say).

Which keys to send and what the replies mean is the server's convention
(:class:`~mmact_ctrl.sources.presets.Convention`), settled at connect from the server's metadata and the user's
switches (:mod:`mmact_ctrl.sources.presets.resolve`): a server of ours declares everything in its metadata
(``"mmact"``, see :mod:`~mmact_ctrl.sources.remote.serving`); a foreign server is given a preset (``--preset
libero``) or the pieces; neither is one line, before any episode. The true target (privileged keys) reaches only a
server of ours that asks for it, or one the user chose the ``mmact`` keys for.

Every failure of a call raises (the loop counts it as a rejected chunk and keeps the previous one running): the
wire's own errors (:class:`~mmact_ctrl.sources.openpi.client.WireError`: timeout, lost connection, error frame) and
``ValueError`` for a reply without ``actions``, of the wrong shape, or with NaN (naming the shape or the waypoint).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.sources.action_space import ActionAdapter, ActionSpace
from mmact_ctrl.sources.contract import CAPABILITIES, SourceError
from mmact_ctrl.sources.openpi.client import ClientConfig, PolicyClient
from mmact_ctrl.sources.remote.mapping import KNOWN_ACTIONS_KEY, N_CLIPPED_KEY, SCENE_CAMERAS, TOKENS_KEY, ObsMapping
from mmact_ctrl.sources.presets.resolve import ConventionSwitches, Resolved, resolve


def _mmact_metadata(metadata: dict) -> dict | None:
    meta = metadata.get("mmact") if isinstance(metadata, dict) else None
    return meta if isinstance(meta, dict) else None


class RemoteSource:
    """A ``ChunkSource`` over a policy server.

    Args:
        url: ``ws://host:port``.
        switches: what the user said of the server's convention (``--preset`` and the pieces' switches).
        config: the client's timeouts and retries.
        model: the robot model for joint-space actions and the state's orientation (None: the Panda's).
        scene_cameras: the cameras the scene has (image keys of other cameras get black frames).
        mapping: from Python: the observation mapping (a preset name, a JSON file, a mapping object): the same as
            ``switches.obs_mapping``.
        action_space: from Python: the whole action space (an ``ActionSpace`` or its dict): every action piece said.

    Raises:
        ServerUnreachable: the server cannot be reached (a ``SourceError``: one line naming the URL).
        SourceError: no convention can be settled, or a switch contradicts the server (one line naming both).
    """

    def __init__(self, url: str, switches: ConventionSwitches | None = None, config: ClientConfig = ClientConfig(),
                 model=None, scene_cameras: tuple[str, ...] = SCENE_CAMERAS, *,
                 mapping: "str | ObsMapping | None" = None, action_space: "ActionSpace | dict | None" = None) -> None:
        self.client = PolicyClient(url, config)
        try:
            switches = _fold(switches or ConventionSwitches(), mapping, action_space, self.client.url)
            self.resolved: Resolved = resolve(self.client.metadata, switches, self.client.url, tuple(scene_cameras))
            self._configure(model)
        except Exception:
            self.client.close()
            raise

    # ---- configuration ---------------------------------------------------------------------------------------
    def _configure(self, model) -> None:
        conv = self.resolved.convention
        self._meta = _mmact_metadata(self.client.metadata)
        meta = self._meta or {}
        self.action_token_range: tuple[int, int] | None = None
        try:
            tok = meta.get("action_token_range") if "action_space" in meta else None
            self.action_token_range = None if tok is None else (int(tok[0]), int(tok[1]))
        except (TypeError, ValueError, IndexError) as exc:
            raise SourceError(f"the policy server at {self.name} sent malformed 'mmact' metadata: {exc}") from None
        caps = meta.get("capabilities") or ()
        self.declared_capabilities: frozenset[str] = frozenset(str(c) for c in caps if str(c) in CAPABILITIES)
        if self.resolved.word.scene is not None:
            self.scene = dict(self.resolved.word.scene)
        self.mapping = conv.mapping
        self.space = conv.action
        self.adapter = ActionAdapter(conv.action, model)
        self._rot_nominal = self.adapter.model.fk(self.adapter.model.home_q_rad)[1]
        self.last_actions: np.ndarray | None = None

    @property
    def convention(self):
        """The settled :class:`~mmact_ctrl.sources.presets.Convention`."""
        return self.resolved.convention

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
        who += f"; convention {self.convention.name}"
        caps = ", ".join(sorted(self.declared_capabilities)) or "none"
        return f"{self.name}: {who}; {self.mapping.describe()}; actions {self.space.describe()}; capabilities {caps}"

    # ---- the contract -----------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Nothing to reset remotely (openpi's protocol has no reset message); the connection stays."""

    def close(self) -> None:
        self.client.close()

    def plan(self, observation: Observation, timeout_s: float | None = None) -> ActionChunk:
        """One chunk for ``observation`` (``timeout_s``: this call's limit; None: the client's request timeout)."""
        return self._request(observation, None, timeout_s)

    def plan_inpaint(self, observation: Observation, known: np.ndarray) -> ActionChunk:
        """Real-time chunking over the wire (our extension): ``known`` (n, 7) travels as ``mmact/known_actions``;
        only for a server that declares the ``inpaint`` capability."""
        if "inpaint" not in self.declared_capabilities:
            raise SourceError(f"the policy server at {self.name} does not declare the inpaint capability")
        return self._request(observation, np.ascontiguousarray(known, dtype=np.float64).reshape(-1, 7))

    def _request(self, observation: Observation, known: np.ndarray | None, timeout_s: float | None = None) -> ActionChunk:
        obs = self.mapping.encode(observation, self._rot_nominal)
        if known is not None:
            obs[KNOWN_ACTIONS_KEY] = known
        self.last_actions = None
        reply = self.client.infer(obs, timeout_s)
        self._check_same_server()
        call = self.client.calls[-1]
        if "actions" not in reply:
            raise ValueError(f"{self.name}: the reply has no 'actions' (keys: {sorted(map(str, reply))[:12]})")
        actions = np.asarray(reply["actions"])
        self.last_actions = actions
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


def _fold(switches: ConventionSwitches, mapping, action_space, url: str) -> ConventionSwitches:
    """``switches`` with the Python-side ``mapping`` / ``action_space`` arguments folded in."""
    if isinstance(action_space, dict):
        try:
            action_space = ActionSpace.from_dict(action_space)
        except (TypeError, ValueError) as exc:
            raise SourceError(f"the action space given for {url} is malformed: {exc}") from None
    if action_space is not None and not isinstance(action_space, ActionSpace):
        raise SourceError(f"the action space for {url} must be an ActionSpace or its dict, got {action_space!r}")
    if action_space is not None:
        pieces = ConventionSwitches.from_space(action_space)
        switches = replace(switches, **{p: getattr(pieces, p) for p in pieces.given()})
    if mapping is not None:
        switches = replace(switches, obs_mapping=mapping)
    return switches
