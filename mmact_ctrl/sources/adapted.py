"""A source that speaks another action space, made a ``ChunkSource`` of ours by its space's adapter."""

from __future__ import annotations

from mmact_ctrl.chunk import ActionChunk, Observation
from mmact_ctrl.sources.action_space import ActionAdapter, ActionSpace
from mmact_ctrl.sources.contract import source_name

#: optional members passed through to the wrapped source when it has them
_FORWARDED = ("camera_names", "image_size_px", "prev_frame_gap_s", "scene", "metadata")


class AdaptedSource:
    """Wraps ``inner``, whose ``plan(observation)`` returns an ``(H, D)`` array of actions in ``space`` (default:
    ``inner.action_space``), into a source that returns our task-space ``ActionChunk``. Inpainting is not offered:
    the known prefix is in our space, and turning it back into a joint space would need inverse kinematics the
    source did not ask for.

    Args:
        inner: the wrapped object (``needs_image``, ``plan``; optional ``reset``, ``close``, ``camera_names``, ...).
        space: its action space (None: ``inner.action_space``).
        model: robot model for the joint spaces' forward kinematics (None: the Panda's).
    """

    declared_capabilities = frozenset()

    def __init__(self, inner, space: ActionSpace | None = None, model=None) -> None:
        space = space if space is not None else getattr(inner, "action_space", None)
        if isinstance(space, dict):
            space = ActionSpace.from_dict(space)
        if not isinstance(space, ActionSpace):
            raise ValueError(f"source {source_name(inner)!r}: action_space must be an ActionSpace, got {space!r}")
        self.inner = inner
        self.space = space
        self.adapter = ActionAdapter(space, model)
        self.needs_image = bool(getattr(inner, "needs_image", False))
        self.name = source_name(inner)
        for attr in _FORWARDED:
            if hasattr(inner, attr):
                setattr(self, attr, getattr(inner, attr))

    @property
    def chunk_dt_s(self) -> float:
        return float(self.space.dt_s)

    def reset(self) -> None:
        fn = getattr(self.inner, "reset", None)
        if callable(fn):
            fn()

    def close(self) -> None:
        fn = getattr(self.inner, "close", None)
        if callable(fn):
            fn()

    def plan(self, observation: Observation) -> ActionChunk:
        out = self.inner.plan(observation)
        if isinstance(out, ActionChunk):
            if not self.space.is_native:
                raise ValueError(f"source {self.name!r} declares action space {self.space.describe()} but returned an "
                                 "ActionChunk (our task space): return the (H, D) actions instead")
            return out
        return self.adapter.to_chunk(out, observation)
