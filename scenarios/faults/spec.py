"""The values of a fault: :class:`FaultSpec` (one fault of one episode), :class:`Fault` (one entry of the
registry, ``scenarios.faults.registry.FAULTS``) and :class:`Injection` (the wrapped parts of one episode)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

#: default onset of every fault, s.
DEFAULT_ONSET_S = 1.5
#: default length of a windowed fault, s.
DEFAULT_WINDOW_S = 1.5


@dataclass(frozen=True)
class FaultSpec:
    """One fault of one episode.

    Attributes:
        name: a key of :data:`FAULTS`.
        t_fault_s: onset, s of simulated time.
        duration_s: length of the fault window, s (None: the fault's own default: 1.5 s for windowed faults,
            the tick count of the tick faults, the given silence, to the end of the episode for the moved
            targets).
    """

    name: str
    t_fault_s: float = DEFAULT_ONSET_S
    duration_s: float | None = None

    def __post_init__(self) -> None:
        from scenarios.faults.registry import FAULTS

        if self.name not in FAULTS:
            raise ValueError(f"unknown fault {self.name!r}; expected one of {', '.join(FAULTS)}")
        if not (math.isfinite(self.t_fault_s) and self.t_fault_s >= 0):
            raise ValueError(f"t_fault_s must be a finite number >= 0, got {self.t_fault_s!r}")
        if self.duration_s is not None and not (self.duration_s >= 0):
            raise ValueError(f"duration_s must be >= 0 or None, got {self.duration_s!r}")

    @property
    def fault(self) -> "Fault":
        from scenarios.faults.registry import FAULTS

        return FAULTS[self.name]

    def window_s(self, dt_s: float = 0.001) -> tuple[float, float]:
        """The fault window ``[start, end)`` in s (end may be inf)."""
        f = self.fault
        if f.name == "start_with_velocity":
            return 0.0, 0.0
        if self.duration_s is not None:
            d = float(self.duration_s)
        elif f.ticks is not None:
            d = f.ticks * dt_s
        else:
            d = f.duration_s
        return float(self.t_fault_s), float(self.t_fault_s) + d


@dataclass
class Injection:
    """The wrapped parts of one episode under one fault: pass ``world``, ``source``, ``link`` and
    ``initial_dq_rad_s`` to :func:`~mmact_ctrl.loop.run_episode`. ``applicable`` is False when the fault has
    nothing to act on in this configuration (``mpc_late`` without an MPC). ``close()`` (or leaving the
    ``with`` block) removes the patches made on the controller."""

    spec: FaultSpec
    world: Any
    source: Any
    window_s: tuple[float, float]
    link: Any = None
    initial_dq_rad_s: np.ndarray | None = None
    applicable: bool = True
    _undo: list[Callable[[], None]] = field(default_factory=list, repr=False)

    def close(self) -> None:
        while self._undo:
            self._undo.pop()()

    def __enter__(self) -> "Injection":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class Fault:
    """One entry of :data:`FAULTS`.

    Attributes:
        name: public name.
        kind: ``baseline``, ``source``, ``perception``, ``controller``, ``link``, ``world``.
        description: one line for reports.
        build: ``build(spec, world, source, controller, injection)`` fills in the injection.
        duration_s: default window length, s (inf: to the end of the episode).
        ticks: tick faults: the window is this many control periods.
        unreachable: the target cannot be reached during the fault (no success or recovery is expected).
    """

    name: str
    kind: str
    description: str
    build: Callable[..., None]
    duration_s: float = DEFAULT_WINDOW_S
    ticks: int | None = None
    unreachable: bool = False

