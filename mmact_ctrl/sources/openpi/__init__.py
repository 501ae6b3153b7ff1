"""openpi's websocket policy protocol (websockets + msgpack-numpy), spoken by our client and our server alike: a
protocol package that imports nothing else of this project (another project could vendor these four files).

- :mod:`.codec`: msgpack-numpy frames, byte-compatible with ``openpi_client.msgpack_numpy``;
- :mod:`.client`: :class:`PolicyClient`, a synchronous client with bounded connects and per-request timeouts;
- :mod:`.server`: :class:`PolicyServer`, the server loop for any ``infer(obs) -> dict`` policy (foreground or a
  background thread);
- :mod:`.bench`: the protocol's overhead on loopback (``python -m mmact_ctrl.sources.openpi.bench``).

What our stack does over it (observation mappings, conventions, the remote chunk source, serving a source of ours)
lives in ``mmact_ctrl.sources.remote``. openpi's own ``openpi-client`` is not a dependency (it pins numpy < 2); the
tests drive our server with it, and our client with openpi's own server (``openpi-server``), both installed with
``pip install --no-deps``.
"""

from .client import (CallRecord, ClientConfig, ConnectionLost, PolicyClient, ProtocolError, RequestTimeout,
                     ServerError, ServerUnreachable, WireError)
from .codec import FrameError, packb, unpackb
from .server import DEFAULT_PORT, ListenError, PolicyServer, ServerHandle

__all__ = ["CallRecord", "ClientConfig", "ConnectionLost", "PolicyClient", "ProtocolError", "RequestTimeout",
           "ServerError", "ServerUnreachable", "WireError", "FrameError", "packb", "unpackb", "DEFAULT_PORT",
           "ListenError", "PolicyServer", "ServerHandle"]
