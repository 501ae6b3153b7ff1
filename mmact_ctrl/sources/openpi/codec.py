"""msgpack-numpy frames, byte-compatible with openpi's ``openpi_client.msgpack_numpy``.

An ``np.ndarray`` travels as the map ``{b"__ndarray__": True, b"data": <raw bytes, C order>, b"dtype": dtype.str,
b"shape": shape}``, a numpy scalar as ``{b"__npgeneric__": True, b"data": scalar.item(), b"dtype": dtype.str}``;
everything else as plain msgpack (str keys stay str, bytes stay bytes, tuples arrive as lists). No pickle: arrays
of object or void (structured) dtype cannot be sent and raise :class:`FrameError` (a ``ValueError``); so do
numpy scalars whose value msgpack cannot hold (complex, datetime).

Packing a C-contiguous array hands msgpack the array's own buffer (no copy); unpacked arrays are read-only views
of the received frame's bytes (copy them to write).
"""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np

#: dtype kinds that cannot travel without pickle: object, void (structured / opaque records)
REFUSED_KINDS = ("O", "V")
#: numpy scalar kinds whose ``.item()`` msgpack can pack (bool, ints, floats, bytes, str)
_SCALAR_KINDS = ("b", "i", "u", "f", "S", "U")
#: dtype kinds the buffer protocol does not export (datetime64, timedelta64): packed from a copy
_NO_BUFFER_KINDS = ("M", "m")


class FrameError(ValueError):
    """A frame that cannot be packed or unpacked (one line naming the value)."""


def _encode(obj: Any) -> Any:
    """msgpack ``default`` hook: ndarray and numpy scalars as openpi encodes them."""
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind in REFUSED_KINDS:
            raise FrameError(f"cannot send an array of dtype {obj.dtype} (shape {obj.shape}): object and structured "
                             "arrays would need pickle; send numbers, strings or bytes")
        # the array's own buffer where the buffer protocol allows it (not datetimes): the same bytes, no copy
        data = obj.data if obj.flags.c_contiguous and obj.dtype.kind not in _NO_BUFFER_KINDS else obj.tobytes()
        return {b"__ndarray__": True, b"data": data, b"dtype": obj.dtype.str, b"shape": obj.shape}
    if isinstance(obj, np.generic):
        if obj.dtype.kind not in _SCALAR_KINDS:
            raise FrameError(f"cannot send a numpy scalar of dtype {obj.dtype} ({obj!r}): msgpack holds bool, int, "
                             "float, bytes and str scalars; send it as a 0-d array")
        return {b"__npgeneric__": True, b"data": obj.item(), b"dtype": obj.dtype.str}
    raise FrameError(f"cannot send an object of type {type(obj).__name__} ({obj!r:.80})")


def _decode(obj: dict) -> Any:
    """msgpack ``object_hook``: the maps :func:`_encode` writes back into numpy objects."""
    if b"__ndarray__" in obj:
        dtype = _dtype(obj.get(b"dtype"))
        shape = tuple(obj.get(b"shape") or ())
        data = obj.get(b"data")
        try:
            return np.ndarray(buffer=data, dtype=dtype, shape=shape)
        except (TypeError, ValueError) as exc:
            size = len(data) if isinstance(data, (bytes, bytearray)) else type(data).__name__
            raise FrameError(f"bad array in frame: dtype {dtype}, shape {shape}, {size} data bytes ({exc})") from None
    if b"__npgeneric__" in obj:
        return _dtype(obj.get(b"dtype")).type(obj.get(b"data"))
    return obj


def _dtype(text) -> np.dtype:
    try:
        dtype = np.dtype(text)
    except (TypeError, ValueError):
        raise FrameError(f"bad dtype in frame: {text!r}") from None
    if dtype.kind in REFUSED_KINDS:
        raise FrameError(f"refusing an array of dtype {dtype} in frame: object and structured arrays need pickle")
    return dtype


def packer() -> msgpack.Packer:
    """A reusable packer (keep one per connection: it reuses its buffer)."""
    return msgpack.Packer(default=_encode)


def packb(obj: Any) -> bytes:
    """One frame's bytes for ``obj`` (dicts, lists, numbers, str, bytes, numpy arrays and scalars)."""
    return msgpack.packb(obj, default=_encode)


def unpackb(data: bytes) -> Any:
    """The object in one frame (raises ``ValueError`` naming what is malformed)."""
    try:
        return msgpack.unpackb(data, object_hook=_decode)
    except FrameError:
        raise
    except Exception as exc:  # noqa: BLE001 - msgpack's own errors (ExtraData, FormatError, ...) as one kind
        why = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        raise FrameError(f"undecodable frame of {len(data)} bytes ({why})") from None
