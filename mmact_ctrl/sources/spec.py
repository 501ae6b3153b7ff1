"""One frozen description of what a chunk source is and can do, read from it once (the one place that reads the
optional members of the contract, ``mmact_ctrl.sources.contract``, by name)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from mmact_ctrl.sources.contract import capabilities, source_name


def _float_or(value, default: float) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return default
    return value if math.isfinite(value) else default


@dataclass(frozen=True)
class SourceSpec:
    """What a source declares (its optional members, read once).

    Attributes:
        name: how reports name it.
        needs_image: whether ``plan`` reads ``Observation.image``.
        camera_names: the scene cameras it wants, in order (empty: the world's default).
        image_size_px: the side of the frames it wants (None: the world's default).
        prev_frame_gap_s: > 0: it also wants the frames this long before (``Observation.prev_image``), s.
        chunk_dt_s: its waypoint spacing as declared, s (None: not declared; checked where it is used: a malformed
            one fails the requests that read it, each a counted rejection).
        action_token_range: the half-open range of the action tokens its chunks carry (None: no tokens).
        capabilities: the optional capabilities it provides (``inpaint``).
        scene: the ``make_world`` settings of the scenes it was made for (``plane_z_m``, ``n_objects``).
        answers_concurrently: its ``plan`` (and ``plan_inpaint``) is a pure function of the observation, safe to call
            from another thread while the world steps: simulated time may run it ahead (``mmact_ctrl.lookahead``).
            Read from the source's class, never through a wrapper's delegation: a wrapper may add what is not.
    """

    name: str
    needs_image: bool = False
    camera_names: tuple[str, ...] = ()
    image_size_px: int | None = None
    prev_frame_gap_s: float = 0.0
    chunk_dt_s: "float | None" = None
    action_token_range: tuple[int, int] | None = None
    capabilities: frozenset[str] = frozenset()
    scene: dict = field(default_factory=dict)
    answers_concurrently: bool = False

    @classmethod
    def of(cls, source) -> "SourceSpec":
        """The spec of ``source`` (its members read once, with their defaults when absent)."""
        get = lambda name: getattr(source, name, None)  # noqa: E731 - the contract's optional members, by name
        tok, size, dt = get("action_token_range"), get("image_size_px"), get("chunk_dt_s")
        return cls(name=source_name(source), needs_image=bool(get("needs_image")),
                   camera_names=tuple(get("camera_names") or ()), image_size_px=int(size) if size else None,
                   prev_frame_gap_s=_float_or(get("prev_frame_gap_s") or 0.0, 0.0),
                   chunk_dt_s=dt,
                   action_token_range=None if tok is None else tok, capabilities=capabilities(source),
                   scene=dict(get("scene") or {}),
                   answers_concurrently=getattr(type(source), "answers_concurrently", False) is True)
