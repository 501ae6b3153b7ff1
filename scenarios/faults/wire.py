"""Wire faults: the episode's source served over openpi's protocol on 127.0.0.1, with the wire failing in the window.

Each ``wire_*`` fault of ``scenarios.faults.injectors`` puts the cell's source (the expert, our policy, a plugin)
behind a real websocket server in a thread of this process (``mmact_ctrl.sources.openpi``) and drives the episode
through a real :class:`~mmact_ctrl.sources.openpi.RemoteSource`. In the fault window the server

``error_frame``  raises in ``infer``: it sends the traceback as a text frame and closes the connection (openpi's way);
``slow``         answers after the client's request timeout (the client gives up; the late reply is never taken);
``bad_shape``    answers actions of the wrong shape;
``nan``          answers NaN actions;
``dies``         is stopped (the port closes) at the first query in the window and started again, on the same
                 port, at the first query after it.

Every one of them must end as a counted rejection (``source_raised``) that the 1 kHz loop survives; after the window
the source answers again. The client's timeouts are short here (:data:`WIRE_CLIENT`) so that the suite stays quick.
"""

from __future__ import annotations

import time

import numpy as np

from mmact_ctrl.sources.remote import RemoteSource
from mmact_ctrl.sources.openpi.client import ClientConfig
from mmact_ctrl.sources.openpi.server import PolicyServer
from mmact_ctrl.sources.remote.serving import SourcePolicy

BEHAVIOURS: tuple[str, ...] = ("error_frame", "slow", "bad_shape", "nan", "dies")
#: the client of the wire faults: a request times out after 0.3 s, a lost server is retried once for 0.3 s
WIRE_CLIENT = ClientConfig(connect_timeout_s=2.0, connect_tries=3, retry_wait_s=0.2, request_timeout_s=0.3,
                           reconnect_timeout_s=0.3)
#: how long ``slow`` makes a reply wait: past the client's request timeout, s
SLOW_REPLY_S = 0.5
_EPS_S = 1e-9


def _in(window: tuple[float, float], t_s: float) -> bool:
    return window[0] - _EPS_S <= t_s < window[1] - _EPS_S


class _FaultyPolicy:
    """``SourcePolicy`` whose answers to observations in the window are spoiled by ``behaviour``."""

    def __init__(self, policy: SourcePolicy, behaviour: str, window: tuple[float, float]) -> None:
        self.policy, self.behaviour, self.window = policy, behaviour, window
        self.metadata = policy.metadata
        self.faulty_calls = 0

    def infer(self, obs: dict) -> dict:
        t0_s = float(np.asarray(obs.get("mmact/t0_s", -1.0)))
        reply = self.policy.infer(obs)
        if not _in(self.window, t0_s) or self.behaviour == "dies":
            return reply
        self.faulty_calls += 1
        b = self.behaviour
        if b == "error_frame":
            raise RuntimeError(f"injected fault: the policy server crashed at t={t0_s:.3f} s")
        if b == "slow":
            time.sleep(SLOW_REPLY_S)
        elif b == "bad_shape":
            reply["actions"] = np.zeros((len(reply["actions"]), 5))
        elif b == "nan":
            reply["actions"] = np.full_like(reply["actions"], np.nan)
        return reply


class WireServed:
    """A chunk source served on 127.0.0.1 with a faulty wire, and the remote source the episode runs on.

    Use as a context manager (or call :meth:`close`): the server thread stops."""

    def __init__(self, source, behaviour: str, window: tuple[float, float], scene: dict | None = None) -> None:
        if behaviour not in BEHAVIOURS:
            raise ValueError(f"unknown wire fault behaviour {behaviour!r}; expected one of {BEHAVIOURS}")
        self.behaviour, self.window = behaviour, window
        self.policy = _FaultyPolicy(SourcePolicy(source, scene=scene), behaviour, window)
        self.handle = PolicyServer(self.policy, host="127.0.0.1", port=0).start()
        self.port = self.handle.port
        self.remote = RemoteSource(self.handle.url, config=WIRE_CLIENT)
        self.killed = False

    # the episode's chunk source: the remote one, with the server's death and return on the episode's clock
    @property
    def needs_image(self) -> bool:
        return self.remote.needs_image

    def __getattr__(self, name: str):
        return getattr(self.remote, name)

    @property
    def declared_capabilities(self) -> frozenset[str]:
        return self.remote.declared_capabilities

    def _clock(self, t_s: float) -> None:
        if self.behaviour != "dies":
            return
        if _in(self.window, t_s) and not self.killed:
            self.handle.stop()
            self.killed = True
        elif self.killed and t_s >= self.window[1] - _EPS_S and not self.handle.running:
            self.handle = PolicyServer(self.policy, host="127.0.0.1", port=self.port).start()

    def plan(self, observation):
        self._clock(observation.t0_s)
        return self.remote.plan(observation)

    def plan_inpaint(self, observation, known):
        self._clock(observation.t0_s)
        return self.remote.plan_inpaint(observation, known)

    def close(self) -> None:
        self.remote.close()
        if self.handle.running:
            self.handle.stop()

    def __enter__(self) -> "WireServed":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
