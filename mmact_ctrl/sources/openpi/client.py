"""A synchronous client of openpi's websocket policy protocol (``ws://host:port``, msgpack-numpy frames).

On connect the server sends one binary frame, its metadata (a dict); then each request is one binary frame (the
observation dict) answered by one binary frame (a dict with ``"actions"`` (H, D) and, from openpi's server and ours,
``"policy_timing": {"infer_ms"}`` and ``"server_timing": {"infer_ms", "prev_total_ms"}``). A server that fails
sends the traceback as a text frame and closes the connection.

Every failure is bounded in time and raised as a :class:`WireError` subclass with one line naming the URL:

``ServerUnreachable``  connecting failed ``connect_tries`` times (each within ``connect_timeout_s``); also a
                       ``ConnectionError``, so the command lines print it as one line;
``RequestTimeout``     no reply within ``request_timeout_s``;
``ConnectionLost``     the connection closed under a request (the server stopped or crashed);
``ServerError``        the server answered a text frame (its error); carries the exception line and the full text;
``ProtocolError``      a frame that is not a msgpack dict.

After any failure the connection is dropped: a reply that arrives late can never be read as the answer to a later
request. The next :meth:`PolicyClient.infer` reconnects with one quick attempt (``reconnect_timeout_s``), so while
the server is down each call fails fast, and calls succeed again once it is back. The connection is direct (no
proxy) and TCP_NODELAY is set (websockets' default).
"""

from __future__ import annotations

import collections
import inspect
import math
import time
from dataclasses import dataclass

from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import ClientConnection, connect

from . import codec


#: ``connect`` switches of the installed websockets that exist there: a direct connection (never through a proxy the
#: environment names), and the connection object itself rather than a context manager (websockets >= 17 warns
#: unless ``legacy=True`` says so)
_CONNECT_OPTIONAL = {k: v for k, v in (("proxy", None), ("legacy", True)) if k in inspect.signature(connect).parameters}


class WireError(Exception):
    """Any failure of the policy server link (one line, naming the URL)."""


class ServerUnreachable(WireError, ConnectionError):
    """The server could not be reached (at connect time: the source cannot be built)."""


class RequestTimeout(WireError, TimeoutError):
    """No reply within the request timeout."""


class ConnectionLost(WireError, ConnectionError):
    """The connection closed while a request was in flight."""


class ServerError(WireError):
    """The server answered a text frame: its error. ``text`` holds all of it (openpi sends the traceback)."""

    def __init__(self, message: str, text: str) -> None:
        super().__init__(message)
        self.text = text


class ProtocolError(WireError, ValueError):
    """A frame that does not follow the protocol (not a msgpack dict)."""


@dataclass(frozen=True)
class ClientConfig:
    """How long the client waits, and how often it tries.

    Attributes:
        connect_timeout_s: one connection attempt (TCP + websocket handshake + the metadata frame), s.
        connect_tries: attempts at the first connection before :class:`ServerUnreachable`.
        retry_wait_s: wait between those attempts, s.
        request_timeout_s: one request, from sending the observation to the whole reply, s.
        reconnect_timeout_s: the one quick attempt a call makes after the connection was dropped, s.
        close_timeout_s: how long dropping a connection waits for the closing handshake, s.
        history_len: how many calls :attr:`PolicyClient.calls` keeps.
    """

    connect_timeout_s: float = 5.0
    connect_tries: int = 3
    retry_wait_s: float = 1.0
    request_timeout_s: float = 10.0
    reconnect_timeout_s: float = 1.0
    close_timeout_s: float = 0.5
    history_len: int = 100_000

    def __post_init__(self) -> None:
        for name in ("connect_timeout_s", "request_timeout_s", "reconnect_timeout_s", "close_timeout_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"ClientConfig.{name} must be a finite number of seconds > 0, got {value!r}")
        if not (isinstance(self.retry_wait_s, (int, float)) and math.isfinite(self.retry_wait_s) and self.retry_wait_s >= 0):
            raise ValueError(f"ClientConfig.retry_wait_s must be a number of seconds >= 0, got {self.retry_wait_s!r}")
        if not (isinstance(self.connect_tries, int) and self.connect_tries >= 1):
            raise ValueError(f"ClientConfig.connect_tries must be an integer >= 1, got {self.connect_tries!r}")
        if not (isinstance(self.history_len, int) and self.history_len >= 1):
            raise ValueError(f"ClientConfig.history_len must be an integer >= 1, got {self.history_len!r}")


@dataclass(frozen=True)
class CallRecord:
    """One :meth:`PolicyClient.infer` call: its round trip (ms, send to reply decoded, reconnecting included), the
    reply's ``server_timing.infer_ms`` / ``policy_timing.infer_ms`` (None when absent), or the error it raised."""

    round_trip_ms: float
    server_infer_ms: float | None = None
    policy_infer_ms: float | None = None
    error: str | None = None


def _timing_ms(reply: dict, group: str) -> float | None:
    value = reply.get(group)
    value = value.get("infer_ms") if isinstance(value, dict) else None
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def _error_line(text: str) -> str:
    """The informative line of a server's error text: the exception line of a traceback, else the first line."""
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    if not lines:
        return "(empty error frame)"
    if lines[0].startswith("Traceback"):
        return lines[-1]
    return lines[0]


def normalize_url(url: str) -> str:
    """``ws://host:port`` from ``url`` (``host:port`` gets the ``ws://`` scheme; ``wss://`` is kept)."""
    text = str(url).strip()
    if not text:
        raise ValueError("policy server URL is empty: give ws://HOST:PORT")
    if "://" not in text:
        text = "ws://" + text
    if not text.startswith(("ws://", "wss://")):
        raise ValueError(f"policy server URL {url!r} must start with ws:// (or wss://)")
    return text


class PolicyClient:
    """One connection to a policy server; :meth:`infer` sends an observation dict and returns the reply dict.

    Connects on construction (raises :class:`ServerUnreachable` after ``config.connect_tries`` attempts) and reads the
    metadata frame (:attr:`metadata`). Not thread-safe: one caller at a time.

    Args:
        url: ``ws://host:port`` (``host:port`` works too).
        config: timeouts and retries.
    """

    def __init__(self, url: str, config: ClientConfig = ClientConfig()) -> None:
        self.url = normalize_url(url)
        self.config = config
        self.metadata: dict = {}
        self.connects = 0
        self.calls: collections.deque[CallRecord] = collections.deque(maxlen=config.history_len)
        self._conn: ClientConnection | None = None
        self._packer = codec.packer()
        last = ""
        for attempt in range(config.connect_tries):
            if attempt:
                time.sleep(config.retry_wait_s)
            try:
                self._connect(config.connect_timeout_s)
                return
            except ServerUnreachable as exc:
                last = str(exc)
        n = config.connect_tries
        raise ServerUnreachable(f"{last} (gave up after {n} {'try' if n == 1 else 'tries'})")

    @property
    def connected(self) -> bool:
        return self._conn is not None

    def _connect(self, timeout_s: float) -> None:
        """One attempt: connect and read the metadata frame, or :class:`ServerUnreachable`."""
        t0 = time.monotonic()
        try:
            conn = connect(self.url, compression=None, max_size=None, open_timeout=timeout_s,
                           close_timeout=self.config.close_timeout_s, **_CONNECT_OPTIONAL)
        except InvalidURI as exc:
            raise ServerUnreachable(f"policy server URL {self.url!r} is not valid: {exc}") from None
        except (OSError, TimeoutError, InvalidHandshake) as exc:
            why = str(exc) or type(exc).__name__
            raise ServerUnreachable(f"cannot connect to the policy server at {self.url}: {why}") from None
        try:
            first = conn.recv(timeout=max(1e-3, timeout_s - (time.monotonic() - t0)))
        except TimeoutError:
            conn.close()
            raise ServerUnreachable(f"the policy server at {self.url} sent no metadata frame within {timeout_s:g} s") from None
        except ConnectionClosed as exc:
            raise ServerUnreachable(f"the policy server at {self.url} closed the connection before its metadata "
                                    f"frame ({exc})") from None
        if isinstance(first, str):
            conn.close()
            raise ServerUnreachable(f"the policy server at {self.url} answered an error instead of its metadata: "
                                    f"{_error_line(first)}")
        try:
            metadata = codec.unpackb(first)
        except ValueError as exc:
            conn.close()
            raise ServerUnreachable(f"the policy server at {self.url} sent an unreadable metadata frame: {exc}") from None
        if not isinstance(metadata, dict):
            conn.close()
            raise ServerUnreachable(f"the policy server at {self.url} sent metadata of type {type(metadata).__name__}, "
                                    "not a dict (is it an openpi policy server?)")
        self._conn, self.metadata = conn, metadata
        self.connects += 1

    def _drop(self) -> None:
        conn, self._conn = self._conn, None
        if conn is not None:
            try:
                conn.close()
            except Exception:  # noqa: BLE001 - the connection is being thrown away; nothing to report
                pass

    def infer(self, obs: dict, timeout_s: float | None = None) -> dict:
        """Send ``obs`` and return the server's reply dict (within ``timeout_s``, default
        ``config.request_timeout_s``); every outcome is recorded in :attr:`calls`."""
        t0 = time.perf_counter()
        data = self._packer.pack(obs)  # a bad observation (FrameError) is the caller's, not the link's: no drop
        try:
            reply = self._exchange(data, self.config.request_timeout_s if timeout_s is None else float(timeout_s))
        except Exception as exc:
            self._drop()  # a late reply must never answer a later request
            self.calls.append(CallRecord((time.perf_counter() - t0) * 1e3, error=f"{type(exc).__name__}: {exc}"[:200]))
            raise
        self.calls.append(CallRecord((time.perf_counter() - t0) * 1e3, _timing_ms(reply, "server_timing"),
                                     _timing_ms(reply, "policy_timing")))
        return reply

    def _exchange(self, data: bytes, timeout_s: float) -> dict:
        if self._conn is None:
            self._connect(self.config.reconnect_timeout_s)
        conn = self._conn
        try:
            conn.send(data)
            reply = conn.recv(timeout=timeout_s)
        except TimeoutError:
            raise RequestTimeout(f"the policy server at {self.url} did not answer within {timeout_s:g} s") from None
        except ConnectionClosed as exc:
            raise ConnectionLost(f"the connection to the policy server at {self.url} closed during a request "
                                 f"({exc})") from None
        except OSError as exc:
            raise ConnectionLost(f"the connection to the policy server at {self.url} failed: {exc}") from None
        if isinstance(reply, str):
            raise ServerError(f"the policy server at {self.url} failed: {_error_line(reply)}", reply)
        try:
            out = codec.unpackb(reply)
        except ValueError as exc:
            raise ProtocolError(f"the policy server at {self.url} sent an unreadable reply: {exc}") from None
        if not isinstance(out, dict):
            raise ProtocolError(f"the policy server at {self.url} replied a {type(out).__name__}, not a dict")
        return out

    def close(self) -> None:
        """Close the connection (idempotent); a later :meth:`infer` reconnects."""
        self._drop()

    def __enter__(self) -> "PolicyClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
