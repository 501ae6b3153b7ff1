"""What a chunk source must have, what it may have, and the check a mode makes before an episode starts.

The contract (``mmact_ctrl.chunk.ChunkSource``, documented in the README, "Bring your own policy"):

required
    ``needs_image`` (bool): whether ``plan`` reads ``Observation.image`` (rendering costs ~10 ms per view);
    ``plan(observation)``: an ``ActionChunk`` in our task space, or, for a source that declares
    ``action_space`` (``mmact_ctrl.sources.action_space.ActionSpace``), an ``(H, D)`` array of actions in that
    space, which :class:`~mmact_ctrl.sources.adapted.AdaptedSource` converts.
optional (a capability each; a mode that needs one checks it with :func:`require_capabilities` before the episode)
    ``plan_inpaint(observation, known)``: capability ``inpaint`` (``--mode inpaint``): ``known`` (n, 7) are the
    waypoints that run while the chunk is computed (at ``t0 + (i + 1) dt``), to be kept; the rest is filled in.
optional (read when present)
    ``reset()``: called at the start of every episode; ``close()``: when the run ends;
    ``camera_names`` (tuple of str): the scene cameras ``Observation.image`` must hold, in that order;
    ``image_size_px`` (int): the side of the square camera frames it wants;
    ``prev_frame_gap_s`` (float > 0): it also wants ``Observation.prev_image``, the frames that long before;
    ``chunk_dt_s`` (float): its waypoint spacing (inpainting's known prefix is sampled at it);
    ``action_token_range`` ((low, high)): half-open range of the action tokens it returns in ``ActionChunk.tokens``;
    ``scene`` (dict): ``make_world`` settings of the scenes it was made for (``plane_z_m``, ``n_objects``).
"""

from __future__ import annotations

from typing import Iterable

#: every optional capability a mode may need: name -> the member that provides it, as the error names it
CAPABILITIES: dict[str, str] = {
    "inpaint": "plan_inpaint(observation, known) -> ActionChunk",
}


class SourceError(ValueError):
    """A chunk source that cannot be built or cannot serve the requested modes (one line, naming it)."""


def source_name(source) -> str:
    """How errors and reports name ``source``: its ``name`` attribute, else its class."""
    name = getattr(source, "name", None)
    return str(name) if isinstance(name, str) and name else type(source).__name__


def capabilities(source) -> frozenset[str]:
    """The optional capabilities ``source`` provides (``declared_capabilities`` when it says so itself, as a
    wrapper or a remote source does; else what its members show)."""
    declared = getattr(source, "declared_capabilities", None)
    if declared is not None:
        return frozenset(declared)
    have = set()
    if callable(getattr(source, "plan_inpaint", None)):
        have.add("inpaint")
    return frozenset(have)


def require_capabilities(source, needs: Iterable[str], mode: str) -> None:
    """Raise :class:`SourceError` (one line naming the source, the mode and what is missing) unless ``source``
    provides every capability in ``needs``."""
    missing = sorted(set(needs) - capabilities(source))
    if missing:
        what = "; ".join(f"{m}: {CAPABILITIES.get(m, m)}" for m in missing)
        raise SourceError(f"source {source_name(source)!r} cannot run --mode {mode}: it lacks {what}")


def check_source(obj, name: str):
    """``obj`` if it satisfies the required part of the contract, else :class:`SourceError` naming ``name``."""
    if not callable(getattr(obj, "plan", None)):
        raise SourceError(f"{name} returned {type(obj).__name__}, which is not a chunk source: it has no "
                          "plan(observation) method")
    needs_image = getattr(obj, "needs_image", None)
    if not isinstance(needs_image, (bool, int)) or isinstance(needs_image, float):
        raise SourceError(f"{name} returned {type(obj).__name__}, which is not a chunk source: it needs a bool "
                          f"attribute needs_image (got {needs_image!r})")
    gap = getattr(obj, "prev_frame_gap_s", 0.0) or 0.0
    if not (isinstance(gap, (int, float)) and gap >= 0):
        raise SourceError(f"{name}: prev_frame_gap_s must be a number of seconds >= 0, got {gap!r}")
    return obj
