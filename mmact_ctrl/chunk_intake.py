"""Where chunks enter the 1 kHz loop: a chunk source's faults stop here and are counted, never raised.

A chunk source is the least trusted part of the stack (a policy server can crash, hang, answer late or answer
garbage). :class:`ChunkIntake` calls it, checks what comes back, queues valid chunks by the time they become
active, and checks each again when it is due:

at the call (:meth:`ChunkIntake.request`)
    ``source_raised``  the call raised (a crashed server, a NaN chunk that ``ActionChunk`` refused, a timeout);
    ``not_a_chunk``    it returned something that is not an ``ActionChunk`` (``None`` is not a fault: nothing
                       arrived, the watchdog handles silence);
    ``bad_shape``      waypoints not ``(H >= 1, 7)``;
    ``nonfinite``      NaN or inf waypoints;
    ``bad_time``       a spacing that is not a finite positive number, or an observation time that is not the
                       observation's;
    ``bad_tokens``     tokens of the wrong shape or kind (not integers), or outside the source's declared action
                       token range (``source.action_token_range``, a half-open ``(low, high)``), when present;
when it is due (:meth:`ChunkIntake.admit`)
    ``stale``          nothing of it is left to run (it ends before now: e.g. a latency spike);
    ``out_of_order``   its observation is not newer than that of the chunk already running;
    ``splice``         its position when it becomes active (retargeting included) is farther than
                       ``splice_radius_m`` from the reference being executed (see
                       ``HybridController.splice_distance_m``): a jump the robot should not be asked to make.

A rejected chunk leaves the previous chunk running. ``rejections`` counts each reason; ``events`` keeps
``(t_s, reason, detail)`` for the report; ``source_errors`` keeps the source's own words whole (a policy server's
error text: openpi sends its traceback), once per distinct text, with how often and when first.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np

from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.reference import ChunkReference

#: distinct error texts kept per episode (each whole)
MAX_ERROR_TEXTS = 10

REJECT_REASONS: tuple[str, ...] = ("source_raised", "not_a_chunk", "bad_shape", "nonfinite", "bad_time", "bad_tokens",
                                   "stale", "out_of_order", "splice")


@dataclass(order=True)
class Pending:
    """A valid chunk waiting for its activation time ``t_active_s``."""

    t_active_s: float
    seq: int
    chunk: ActionChunk = field(compare=False)
    target_at_obs_m: np.ndarray | None = field(compare=False, default=None)
    ee_at_obs_m: np.ndarray | None = field(compare=False, default=None)  # the TCP the chunk was planned from


def chunk_problem(chunk, observation: Observation, token_range: tuple[int, int] | None) -> str | None:
    """Why ``chunk`` (the answer to ``observation``) cannot be executed, as a reason of :data:`REJECT_REASONS`
    (None: it can)."""
    if not isinstance(chunk, ActionChunk):
        return "not_a_chunk"
    w = np.asarray(chunk.waypoints)
    if w.ndim != 2 or w.shape[1] != 7 or w.shape[0] < 1:
        return "bad_shape"
    if not np.all(np.isfinite(w)):
        return "nonfinite"
    dt = chunk.dt_s
    if not (isinstance(dt, (int, float, np.floating)) and np.isfinite(dt) and dt > 0):
        return "bad_time"
    if not (np.isfinite(chunk.t0_s) and abs(float(chunk.t0_s) - observation.t0_s) <= 1e-9):
        return "bad_time"
    if chunk.tokens is not None:
        tok = np.asarray(chunk.tokens)
        if tok.shape != w.shape or not np.issubdtype(tok.dtype, np.integer):
            return "bad_tokens"
        if token_range is not None and (tok.min() < token_range[0] or tok.max() >= token_range[1]):
            return "bad_tokens"
    return None


class ChunkIntake:
    """Calls the chunk source safely, validates, queues by activation time, admits when due.

    Args:
        splice_radius_m: largest admissible distance between a new chunk's position at its activation and the
            reference being executed then, m.
        token_range: the source's action token range ``(low, high)`` (half-open), or None.
    """

    def __init__(self, splice_radius_m: float, token_range: tuple[int, int] | None = None) -> None:
        if not splice_radius_m > 0:
            raise ValueError(f"splice_radius_m must be > 0, got {splice_radius_m!r}")
        self.splice_radius_m = float(splice_radius_m)
        self.token_range = token_range
        self.pending: list[Pending] = []
        self.rejections: dict[str, int] = {r: 0 for r in REJECT_REASONS}
        self.events: list[tuple[float, str, str]] = []
        self.source_errors: list[dict] = []
        self.silent_calls = 0
        self._seq = 0

    @property
    def rejected(self) -> int:
        return sum(self.rejections.values())

    def _reject(self, t_s: float, reason: str, detail: str = "") -> None:
        self.rejections[reason] += 1
        self.events.append((float(t_s), reason, detail[:200]))

    def _keep_error(self, t_s: float, exc: Exception) -> None:
        """Keep what the source said: its whole text (``exc.text``, a server's error frame) or the exception."""
        line = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        text = getattr(exc, "text", None)
        text = text if isinstance(text, str) and text.strip() else f"{type(exc).__name__}: {exc}"
        for e in self.source_errors:
            if e["text"] == text:
                e["count"] += 1
                return
        if len(self.source_errors) < MAX_ERROR_TEXTS:
            self.source_errors.append({"t_s": float(t_s), "count": 1, "line": line, "text": text})

    def request(self, call, observation: Observation) -> ActionChunk | None:
        """``call()`` (the source's plan or plan_inpaint), checked: the chunk, or None (nothing arrived or
        rejected: counted)."""
        t = observation.t0_s
        try:
            chunk = call()
        except Exception as exc:  # noqa: BLE001 - any failure of the source is survived here
            self._reject(t, "source_raised", f"{type(exc).__name__}: {exc}")
            self._keep_error(t, exc)
            return None
        if chunk is None:
            self.silent_calls += 1
            return None
        problem = chunk_problem(chunk, observation, self.token_range)
        if problem is not None:
            self._reject(t, problem)
            return None
        return chunk

    def submit(self, t_active_s: float, chunk: ActionChunk, target_at_obs_m: np.ndarray | None,
               ee_at_obs_m: np.ndarray | None = None) -> None:
        """Queue a valid chunk to become active at ``t_active_s``; the queue stays sorted by that time."""
        bisect.insort(self.pending, Pending(float(t_active_s), self._seq, chunk, target_at_obs_m, ee_at_obs_m))
        self._seq += 1

    def due(self, t_s: float) -> list[Pending]:
        """The queued chunks whose activation time has come (oldest first), removed from the queue."""
        if not self.pending or self.pending[0].t_active_s > t_s:
            return []  # the 1 kHz common case: nothing due, nothing allocated
        n = 0
        while n < len(self.pending) and self.pending[n].t_active_s <= t_s:
            n += 1
        out, self.pending[:] = self.pending[:n], self.pending[n:]
        return out

    def admit(self, entry: Pending, t_s: float, running: ChunkReference | None, ref_pos_m: np.ndarray | None = None,
              gap_m: float | None = None) -> bool:
        """Whether the due chunk may become active at ``t_s``, given the chunk ``running`` and either the reference
        position being executed ``ref_pos_m`` (3,; compared with the chunk's own position at ``t_s``) or the jump
        ``gap_m`` the controller computed (retargeting and smoothing included); a refusal is counted."""
        chunk = entry.chunk
        if chunk.end_s <= t_s:
            self._reject(t_s, "stale", f"ended {t_s - chunk.end_s:.3f} s before it became due")
            return False
        if running is not None and chunk.t0_s <= running.chunk.t0_s:
            self._reject(t_s, "out_of_order", f"observed at {chunk.t0_s:.3f} s, running chunk at {running.chunk.t0_s:.3f} s")
            return False
        if gap_m is None:
            start = ChunkReference(chunk=chunk, t_active_s=t_s, target_at_obs_m=None).sample(t_s)[0][:3]
            gap_m = float(np.linalg.norm(start - np.asarray(ref_pos_m, dtype=float)))
        gap = float(gap_m)
        if not gap <= self.splice_radius_m:
            self._reject(t_s, "splice", f"{gap:.3f} m from the reference")
            return False
        return True
