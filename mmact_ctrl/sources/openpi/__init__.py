"""openpi's websocket policy protocol (websockets + msgpack-numpy), spoken by our client and our server alike.

- :mod:`.codec`: msgpack-numpy frames, byte-compatible with ``openpi_client.msgpack_numpy``;
- :mod:`.client`: :class:`PolicyClient`, a synchronous client with bounded connects and per-request timeouts;
- :mod:`.server`: :class:`PolicyServer`, the server loop for any ``infer(obs) -> dict`` policy (foreground or a
  background thread);
- :mod:`.mapping`: which observation keys carry images, state and prompt (presets ``mmact``, ``libero``, ``droid``,
  or a JSON file);
- :mod:`.remote_source`: :class:`RemoteSource`, a chunk source over a server;
- :mod:`.serving`: :class:`SourcePolicy`, a chunk source of ours as an openpi policy, with our metadata;
- :mod:`.bench`: the protocol's overhead on loopback (``python -m mmact_ctrl.sources.openpi.bench``).

Nothing here imports MuJoCo or ``scenarios``. openpi's own ``openpi-client`` package is not a dependency (it pins
numpy < 2); the tests drive our server with it when it is installed with ``pip install --no-deps openpi-client``.
"""

from mmact_ctrl.sources.openpi.client import (CallRecord, ClientConfig, ConnectionLost, PolicyClient, ProtocolError,
                                              RequestTimeout, ServerError, ServerUnreachable, WireError)
from mmact_ctrl.sources.openpi.codec import FrameError, packb, unpackb
from mmact_ctrl.sources.openpi.mapping import (PRESETS, SCENE_CAMERAS, ImageKey, KeyMapping, MmactMapping, StateKey,
                                               load_mapping)
from mmact_ctrl.sources.openpi.remote_source import RemoteSource
from mmact_ctrl.sources.openpi.server import DEFAULT_PORT, ListenError, PolicyServer, ServerHandle
from mmact_ctrl.sources.openpi.serving import SourcePolicy, source_metadata

__all__ = ["CallRecord", "ClientConfig", "ConnectionLost", "PolicyClient", "ProtocolError", "RequestTimeout",
           "ServerError", "ServerUnreachable", "WireError", "FrameError", "packb", "unpackb", "PRESETS",
           "SCENE_CAMERAS", "ImageKey", "KeyMapping", "MmactMapping", "StateKey", "load_mapping", "RemoteSource",
           "DEFAULT_PORT", "ListenError", "PolicyServer", "ServerHandle", "SourcePolicy", "source_metadata"]
