"""The connect check: one observation sent before the first episode, and one block that says what was configured.

:func:`first_call` sends the first episode's first observation to a :class:`RemoteSource` and keeps what came back
(the round trip, the server's own timing, the reply's shape and what looks wrong in it:
:mod:`mmact_ctrl.sources.conformance`), or the server's own words when it failed. A failure there is the user's
to see before any episode (:class:`ConnectError`, one line): a server that raises on the keys we send, a reply that
does not fit the convention.

:class:`ConnectReport` is the block printed at connect and kept in the JSON (``config.connect``): the convention and
where each piece came from, the keys sent (which are black frames, which are privileged), the state's rotation,
the action kind and ``delta_from``, scale, clip, gripper convention, horizon x spacing, and whether the chunks cover
the replan period plus the latency (:func:`coverage`; if not, the replan rate that would).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from mmact_ctrl.chunk import Observation
from mmact_ctrl.sources.conformance import GRIPPER_MEANING, reply_problems
from mmact_ctrl.sources.contract import SourceError
from mmact_ctrl.sources.remote.mapping import KeyMapping

#: the first call may take long: a server compiles its model on its first request (openpi's JAX models do)
FIRST_CALL_TIMEOUT_S = 60.0
#: the slack a chunk must leave after the next one arrives: a fixed part and a share of the latency (its jitter), s
COVER_SLACK_S = 0.05
COVER_SLACK_LATENCY_SHARE = 0.25
#: suggested replan rates are multiples of this, Hz
SUGGEST_STEP_HZ = 0.5
#: the fastest replanning the loop offers (the target channel's rate), Hz
MAX_REPLAN_HZ = 100.0


class ConnectError(SourceError):
    """The first observation was answered with an error or with a reply that does not fit (one line)."""


@dataclass(frozen=True)
class FirstCall:
    """What the first observation brought back.

    Attributes:
        round_trip_ms: send to reply decoded, ms.
        server_infer_ms / policy_infer_ms: the reply's own timing, ms (None when it does not say).
        reply_shape / reply_dtype: of its ``actions``.
        problems: what looks wrong in it for the convention (:func:`~mmact_ctrl.sources.conformance.reply_problems`).
    """

    round_trip_ms: float
    server_infer_ms: float | None
    policy_infer_ms: float | None
    reply_shape: tuple[int, ...]
    reply_dtype: str
    problems: tuple[str, ...] = ()


@dataclass(frozen=True)
class Coverage:
    """Whether each chunk lasts until the next one is active.

    Attributes:
        chunk_s: one chunk's length (horizon x spacing), s.
        period_s: the replan period, s.
        latency_s: the latency a chunk becomes active after (``latency_from`` says which), s.
        covers: ``period_s + latency_s`` plus the slack fits in ``chunk_s``.
        suggested_replan_hz: the slowest replan rate (a multiple of 0.5 Hz) that covers, or None when none does.
    """

    chunk_s: float
    period_s: float
    latency_s: float
    latency_from: str
    covers: bool
    suggested_replan_hz: float | None


def _slack_s(latency_s: float) -> float:
    return COVER_SLACK_S + COVER_SLACK_LATENCY_SHARE * latency_s


def suggest_replan_hz(chunk_s: float, latency_s: float) -> float | None:
    """The slowest replan rate, a multiple of :data:`SUGGEST_STEP_HZ`, at which each chunk of ``chunk_s`` lasts until
    the next is active ``latency_s`` after its query (with slack); None when no rate up to 100 Hz does."""
    room = chunk_s - latency_s - _slack_s(latency_s)
    if room <= 1.0 / MAX_REPLAN_HZ:
        return None
    return min(MAX_REPLAN_HZ, math.ceil((1.0 / room) / SUGGEST_STEP_HZ - 1e-9) * SUGGEST_STEP_HZ)


def coverage(chunk_s: float, replan_hz: float, latency_s: float, latency_from: str) -> Coverage:
    """The :class:`Coverage` of chunks of ``chunk_s`` queried at ``replan_hz`` and active ``latency_s`` later."""
    period = 1.0 / float(replan_hz)
    covers = period + latency_s + _slack_s(latency_s) <= chunk_s
    return Coverage(float(chunk_s), period, float(latency_s), latency_from, bool(covers),
                    None if covers else suggest_replan_hz(chunk_s, latency_s))


def first_call(source, observation: Observation, timeout_s: float = FIRST_CALL_TIMEOUT_S) -> FirstCall:
    """Send ``observation`` to ``source`` (a :class:`RemoteSource`); raises :class:`ConnectError` (one line, the
    server's own words) when the call fails or the reply does not fit the convention."""
    t0 = time.perf_counter()
    waypoints = None
    try:
        waypoints = source.plan(observation, timeout_s=timeout_s).waypoints
    except ValueError as exc:  # the reply does not fit: judged below, with the raw actions
        if source.last_actions is None:
            raise ConnectError(f"the reply to the first observation is unusable: {exc}") from None
    except Exception as exc:  # noqa: BLE001 - the server's failure, in its own words
        line = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ConnectError(f"{line} (on the first observation, before any episode)") from None
    rt_ms = (time.perf_counter() - t0) * 1e3
    call = source.client.calls[-1]
    actions = np.asarray(source.last_actions)
    problems = reply_problems(actions, source.space, observation, waypoints, source.convention.horizon)
    if waypoints is None:
        raise ConnectError(f"the reply to the first observation does not fit the convention {source.convention.name!r}: "
                           f"{problems[0] if problems else 'unusable actions'}")
    return FirstCall(round_trip_ms=call.round_trip_ms if call.error is None else rt_ms,
                     server_infer_ms=call.server_infer_ms, policy_infer_ms=call.policy_infer_ms,
                     reply_shape=tuple(int(n) for n in actions.shape), reply_dtype=str(actions.dtype),
                     problems=tuple(problems))


@dataclass(frozen=True)
class ConnectReport:
    """What was configured for a policy server, and how the first call went (printed at connect, kept in the JSON)."""

    url: str
    server: str
    convention: str
    origin: dict
    keys_sent: tuple[str, ...]
    black_keys: tuple[str, ...]
    privileged_keys: tuple[str, ...]
    state_rotation: str
    actions: str
    gripper: str
    horizon: int | None
    dt_s: float
    first: FirstCall | None
    coverage: Coverage | None
    metadata_keys: tuple[str, ...] = ()
    notes: tuple[str, ...] = field(default=())

    def to_dict(self) -> dict:
        return asdict(self)

    def lines(self) -> list[str]:
        """The block, one fact a line."""
        pieces = sorted({v for v in self.origin.values() if v not in ("default", "not declared")})
        out = [f"policy server {self.url}: {self.server}",
               f"  convention: {self.convention} (set by {', '.join(pieces) or 'nothing'})",
               f"  keys sent: {', '.join(self.keys_sent)}"]
        if self.black_keys:
            out.append(f"  black frames: {', '.join(self.black_keys)} (the scene has no such camera)")
        out.append("  privileged: " + (f"{', '.join(self.privileged_keys)} (the true target, which no real robot has)"
                                       if self.privileged_keys else "none"))
        if self.state_rotation:
            out.append(f"  state rotation: {self.state_rotation}")
        out.append(f"  actions: {self.actions}; gripper {self.gripper}")
        chunk = (f"{self.horizon} x {self.dt_s:g} s = {self.horizon * self.dt_s:g} s" if self.horizon
                 else f"? x {self.dt_s:g} s (chunk length not declared)")
        out.append(f"  chunk: {chunk}")
        f = self.first
        if f is not None:
            timing = f"round trip {f.round_trip_ms:.0f} ms" + (f" (server {f.server_infer_ms:.0f} ms)"
                                                               if f.server_infer_ms is not None else "")
            out.append(f"  first call: actions {f.reply_shape} {f.reply_dtype}, {timing}")
            out += [f"  looks wrong: {p}" if not p.startswith("(note)") else f"  note: {p[7:]}" for p in f.problems]
        c = self.coverage
        if c is not None:
            need = f"replan every {c.period_s:g} s + latency {c.latency_s * 1e3:.0f} ms ({c.latency_from})"
            if c.covers:
                out.append(f"  coverage: {need} fits in a chunk of {c.chunk_s:g} s")
            elif c.suggested_replan_hz is not None:
                out.append(f"  coverage: {need} outlasts a chunk of {c.chunk_s:g} s: the arm brakes (watchdog) between "
                           f"chunks; --replan-hz {c.suggested_replan_hz:g} covers them")
            else:
                out.append(f"  coverage: a chunk of {c.chunk_s:g} s ends before the latency ({c.latency_s * 1e3:.0f} ms) "
                           "is over: no replan rate covers it; the watchdog will stop the arm between chunks")
        out += [f"  note: {n}" for n in self.notes]
        return out


def _keys(mapping) -> tuple[tuple[str, ...], tuple[str, ...]]:
    if not isinstance(mapping, KeyMapping):
        cams = ", ".join(mapping.camera_names) if mapping.needs_image else "no frames"
        return (f"mmact/* (every Observation field; frames of {cams})", "prompt"), ()
    sent = [f"{k.key} {k.size_hw[0]}x{k.size_hw[1]}" + (" rotated 180" if k.rotate_deg == 180 else "")
            for k in mapping.images]
    sent += [f"{k.key} ({k.size}: {'+'.join(k.parts)}, {k.dtype})" for k in mapping.state]
    sent += [f"mmact/{p}" for p in mapping.privileged]
    if mapping.prompt_key:
        sent.append(mapping.prompt_key)
    black = tuple(k.key for k in mapping.images if k.camera not in mapping.scene_cameras)
    return tuple(sent), black


def connect_report(source, first: FirstCall | None, replan_hz: float | None, latency_s: float | None,
                   latency_from: str) -> ConnectReport:
    """The report of ``source`` (a :class:`RemoteSource`) after :func:`first_call`; ``latency_s``: the latency a
    chunk becomes active after (None: the first call's round trip)."""
    conv, word = source.convention, source.resolved.word
    server = (f"a server of ours ({word.source_name or '?'})" if word.ours else "a foreign server")
    if word.action_horizon is not None:
        server += f"; it declares action_horizon {word.action_horizon}"
    keys, black = _keys(conv.mapping)
    horizon = first.reply_shape[-2] if first is not None and len(first.reply_shape) >= 2 else conv.horizon
    cov = None
    if replan_hz and horizon:
        lat = latency_s if latency_s is not None else (first.round_trip_ms / 1e3 if first is not None else 0.0)
        cov = coverage(horizon * float(conv.action.dt_s), replan_hz, lat, latency_from)
    notes = tuple(f"the server's metadata also holds {k!r} (not read)" for k in word.extra_keys)
    return ConnectReport(url=source.name, server=server, convention=conv.name, origin=dict(source.resolved.origin),
                         keys_sent=keys, black_keys=black, privileged_keys=tuple(conv.mapping.privileged_keys),
                         state_rotation=conv.state_rotation, actions=conv.action.describe(),
                         gripper=f"{conv.action.gripper} ({GRIPPER_MEANING[conv.action.gripper]})", horizon=horizon,
                         dt_s=float(conv.action.dt_s), first=first, coverage=cov,
                         metadata_keys=tuple(sorted(map(str, source.metadata))), notes=notes)
