"""Flat vectors with named blocks: the compiled kernels of the 1 kHz path take their constants and state as one
float vector each (one argument, no Python objects inside numba), and this is the one place their offsets are
computed, from the blocks' names and sizes, so no offset is counted by hand."""

from __future__ import annotations

from types import MappingProxyType
from typing import Mapping


def packed_layout(*blocks: tuple[str, int]) -> tuple[Mapping[str, int], int]:
    """``(offsets by name, total length)`` of ``blocks`` ``(name, size)`` packed one after another in order."""
    offsets, at = {}, 0
    for name, size in blocks:
        if name in offsets or size < 1:
            raise ValueError(f"layout block {name!r}: names must be unique and sizes >= 1, got size {size}")
        offsets[name] = at
        at += size
    return MappingProxyType(offsets), at
