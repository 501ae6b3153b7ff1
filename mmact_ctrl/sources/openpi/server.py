"""The server loop of openpi's websocket policy protocol, for any policy object with ``infer(obs: dict) -> dict``.

Per connection, as openpi's ``WebsocketPolicyServer``: send the metadata frame; then for each binary frame: unpack
the observation, call ``policy.infer(obs)``, add ``"server_timing": {"infer_ms", "prev_total_ms"}`` to the reply
(``prev_total_ms``: the previous request's time in the server, from its frame received to its reply sent; absent on
the first), pack and send it. On any exception (a policy that raises, an undecodable frame, a text frame) the
traceback goes back as a text frame and that connection is closed with code 1011; the server keeps serving new
connections. ``GET /healthz`` answers 200 ``OK``.

Unlike openpi's loop, ``infer`` runs in one worker thread beside the event loop (calls stay serialized, one at a
time across connections), so health checks, keep-alive pings and shutdown are answered while a policy thinks, and a
client that leaves mid-request frees its handler at once (the policy's answer is then dropped).

It listens only where the caller says: ``host`` defaults to 127.0.0.1.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import errno
import http
import logging
import sys
import threading
import time
import traceback

from websockets.asyncio.server import Request, Response, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.frames import CloseCode

from . import codec

log = logging.getLogger(__name__)

#: the default port of openpi's servers
DEFAULT_PORT = 8000


class ListenError(OSError):
    """The server could not listen (a port in use, a host that is not this machine's): one line naming both."""


def _health_check(connection: ServerConnection, request: Request) -> Response | None:
    if request.path == "/healthz":
        return connection.respond(http.HTTPStatus.OK, "OK\n")
    return None  # a websocket handshake: go on


def _error_text() -> str:
    return traceback.format_exc()


def carry_torch_threads() -> None:
    """Give the inference thread torch's process-wide intra-op thread count, when torch is loaded: a fresh thread's
    OpenMP pool does not follow ``torch.set_num_threads`` (measured here with one thread set: 200 matmuls of 512 x 512
    took 0.3-0.7 s in the main thread, 1.7-2.0 s in a fresh thread, 0.5-0.8 s once set there; the shipped 3-D policy
    showed no difference, 54-62 ms per chunk either way)."""
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(torch.get_num_threads())


class PolicyServer:
    """Serves ``policy`` (``infer(obs: dict) -> dict``) over the websocket protocol.

    Args:
        policy: the policy; its reply must be a dict (``"actions"`` (H, D) for the protocol's clients).
        metadata: the metadata frame (default: ``policy.metadata`` when it has one, else ``{}``).
        host: the address to listen on (127.0.0.1: this machine only; 0.0.0.0: every interface).
        port: the TCP port (0: a free one, see :attr:`ServerHandle.port`).
        worker_init: called once in the inference thread before its first call (default:
            :func:`carry_torch_threads`).
    """

    def __init__(self, policy, metadata: dict | None = None, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 worker_init=carry_torch_threads) -> None:
        if not callable(getattr(policy, "infer", None)):
            raise ValueError(f"{type(policy).__name__} has no infer(obs) method: it cannot be served")
        if not (isinstance(port, int) and 0 <= port <= 65535):
            raise ValueError(f"port must be an integer in 0..65535, got {port!r}")
        self.policy = policy
        self.metadata = dict(metadata if metadata is not None else getattr(policy, "metadata", None) or {})
        codec.packb(self.metadata)  # a metadata dict that cannot travel is an error now, not at the first client
        self.host = str(host)
        self.port = int(port)
        self.worker_init = worker_init

    async def run(self, on_ready=None, stop: asyncio.Event | None = None) -> None:
        """Serve until ``stop`` is set (or the task is cancelled); ``on_ready(port)`` once listening."""
        worker = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="policy-infer",
                                                       initializer=self.worker_init)
        try:
            try:
                server = await serve(lambda ws: self._handler(ws, worker), self.host, self.port, compression=None,
                                     max_size=None, process_request=_health_check)
            except OSError as exc:
                why = "address already in use" if exc.errno == errno.EADDRINUSE else (exc.strerror or str(exc))
                raise ListenError(exc.errno, f"cannot listen on {self.host}:{self.port}: {why}") from None
            async with server:
                port = server.sockets[0].getsockname()[1]
                log.info("policy server listening on ws://%s:%d", self.host, port)
                if on_ready is not None:
                    on_ready(port)
                await (stop.wait() if stop is not None else asyncio.Future())
        finally:
            worker.shutdown(wait=False, cancel_futures=True)

    def serve_forever(self) -> None:
        """Serve in the foreground until interrupted (Ctrl-C)."""
        asyncio.run(self.run())

    def start(self, timeout_s: float = 10.0) -> "ServerHandle":
        """Serve from a background thread; returns once listening (raises :class:`ListenError` if it cannot)."""
        return ServerHandle(self, timeout_s)

    async def _handler(self, ws: ServerConnection, worker: concurrent.futures.Executor) -> None:
        log.info("connection from %s opened", ws.remote_address)
        loop = asyncio.get_running_loop()
        packer = codec.packer()
        closed = asyncio.ensure_future(ws.wait_closed())
        try:
            await ws.send(packer.pack(self.metadata))
            prev_total_ms = None
            while True:
                try:
                    frame = await ws.recv()
                except ConnectionClosed:
                    break
                t_start = time.perf_counter()
                try:
                    if isinstance(frame, str):
                        raise ValueError("expected a binary msgpack frame (the observation dict), got a text frame")
                    obs = codec.unpackb(frame)
                    t_infer = time.perf_counter()
                    job = loop.run_in_executor(worker, self.policy.infer, obs)
                    await asyncio.wait((job, closed), return_when=asyncio.FIRST_COMPLETED)
                    if not job.done():  # the client left (or the server stops): its answer is dropped
                        break
                    reply = job.result()
                    infer_ms = (time.perf_counter() - t_infer) * 1e3
                    if not isinstance(reply, dict):
                        raise TypeError(f"{type(self.policy).__name__}.infer returned {type(reply).__name__}, not a dict")
                    reply = dict(reply)
                    timing = {"infer_ms": infer_ms}
                    if prev_total_ms is not None:
                        timing["prev_total_ms"] = prev_total_ms
                    reply["server_timing"] = timing
                    data = packer.pack(reply)
                except Exception:  # noqa: BLE001 - any failure goes to the client as text, as openpi does
                    text = _error_text()
                    log.warning("request from %s failed: %s", ws.remote_address, text.strip().splitlines()[-1])
                    try:
                        await ws.send(text)
                        await ws.close(CloseCode.INTERNAL_ERROR, "Internal server error. Traceback included in "
                                       "previous frame.")
                    except ConnectionClosed:
                        pass
                    break
                try:
                    await ws.send(data)
                except ConnectionClosed:
                    break
                prev_total_ms = (time.perf_counter() - t_start) * 1e3
        except ConnectionClosed:
            pass
        finally:
            closed.cancel()
            log.info("connection from %s closed", ws.remote_address)


class ServerHandle:
    """A :class:`PolicyServer` running in a background thread.

    Attributes:
        host, port: where it listens (``port`` is the real one when 0 was asked).
        url: ``ws://host:port``.
        healthz_url: ``http://host:port/healthz``.
    """

    def __init__(self, server: PolicyServer, timeout_s: float = 10.0) -> None:
        self.server = server
        self.host = server.host
        self.port: int | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._error: BaseException | None = None
        ready = threading.Event()

        def on_ready(port: int) -> None:
            self.port = port
            ready.set()

        async def main() -> None:
            self._loop = asyncio.get_running_loop()
            self._stop = asyncio.Event()
            await server.run(on_ready, self._stop)

        def target() -> None:
            try:
                asyncio.run(main())
            except BaseException as exc:  # noqa: BLE001 - handed to start() / stop()
                self._error = exc
            finally:
                ready.set()

        self._thread = threading.Thread(target=target, name=f"policy-server-{server.port}", daemon=True)
        self._thread.start()
        if not ready.wait(timeout_s):
            raise ListenError(errno.ETIMEDOUT, f"the policy server on {server.host}:{server.port} did not start "
                              f"within {timeout_s:g} s")
        if self._error is not None:
            raise self._error

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    @property
    def healthz_url(self) -> str:
        return f"http://{self.host}:{self.port}/healthz"

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Close every connection and stop listening (idempotent); waits up to ``timeout_s`` for the thread."""
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None and self._thread.is_alive():
            try:
                loop.call_soon_threadsafe(stop.set)
            except RuntimeError:  # the loop has just closed
                pass
        self._thread.join(timeout_s)

    def __enter__(self) -> "ServerHandle":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
