"""Classic CDR (XCDR1), the encoding ROS 2 puts on the wire, at the level of its primitives:
a writer and a bounds-checked reader that know alignment, strings and sequences but no message.

``fxis_shm.formats.cdr`` builds the ROS messages out of these. The rules:

* a 4-byte encapsulation header: ``00 01 00 00`` (little endian, what rmw emits; ``00 00`` is
  big endian), then the body;
* every primitive aligned to its own size (at most 8), counted from the first byte after the
  encapsulation header;
* ``string``: uint32 length (with the terminating NUL), the UTF-8 bytes, a NUL;
* ``sequence<T>``: uint32 element count, then the elements (the first aligned to ``sizeof(T)``,
  only if there is one).

The reader raises only :class:`CdrError`, whatever it is given: it reads untrusted network input.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any, TypeAlias

import numpy as np
from numpy.typing import NDArray

from fxis_shm.errors import InvalidArgument

CDR_LE_HEADER = b"\x00\x01\x00\x00"  # classic CDR, little endian, options 0
_BYTE_ORDERS = {b"\x00\x01": "<", b"\x00\x00": ">"}
_PAD = (b"", b"\x00", b"\x00\x00", b"\x00\x00\x00")

Buffer: TypeAlias = bytes | bytearray | memoryview | NDArray[Any]  # anything with a byte buffer


class CdrError(InvalidArgument):
    """Malformed CDR input, or a value that cannot be encoded; the message says which."""


def pad4(buf: bytes) -> bytes:
    """``buf`` zero-padded to a multiple of 4 bytes (copied only if it needs padding).

    DDS wants serialized payloads padded to 4 bytes (rmw_cyclonedds pads its own the same way,
    options left at 0); decoders ignore the padding.
    """
    short = -len(buf) % 4
    return buf if short == 0 else buf + _PAD[short]


def as_byte_view(data: Buffer) -> memoryview:
    """A flat, C-contiguous byte view of ``data``; copies only what is not contiguous."""
    if isinstance(data, np.ndarray):
        view: memoryview = np.ascontiguousarray(data).reshape(-1).view(np.uint8).data
        return view
    view = memoryview(data)
    if not view.c_contiguous:
        view = memoryview(view.tobytes())
    return view if view.format == "B" and view.ndim == 1 else view.cast("B")


class CdrWriter:
    """Writes the small, non-bulk part of a little-endian message; bulk data joins at the end.

    ``pos`` counts from the first byte after the encapsulation header: the origin of alignment.
    """

    __slots__ = ("parts", "pos")

    def __init__(self) -> None:
        self.parts: list[bytes] = [CDR_LE_HEADER]
        self.pos = 0

    def align(self, size: int) -> None:
        pad = -self.pos % size
        if pad:
            self.parts.append(b"\x00" * pad)
            self.pos += pad

    def raw(self, data: bytes) -> None:
        self.parts.append(data)
        self.pos += len(data)

    def pack(self, fmt: str, size: int, align: int, *values: object) -> None:
        self.align(align)
        try:
            self.parts.append(struct.pack(fmt, *values))
        except struct.error as exc:  # out of range, wrong type
            raise CdrError(f"cannot encode {values!r} as {fmt!r}: {exc}") from None
        self.pos += size

    def u8(self, value: int) -> None:
        self.pack("<B", 1, 1, value)

    def u32(self, value: int) -> None:
        self.pack("<I", 4, 4, value)

    def string(self, text: str) -> None:
        data = text.encode("utf-8")
        if b"\x00" in data:
            raise CdrError("CDR strings cannot contain NUL characters")
        self.u32(len(data) + 1)
        self.raw(data + b"\x00")

    def f64_array(self, values: Sequence[float], count: int, name: str) -> None:
        if len(values) != count:
            raise CdrError(f"{name} must have exactly {count} elements, got {len(values)}")
        self.pack(f"<{count}d", 8 * count, 8, *values)

    def finish(self, *bulk: memoryview, pad: bool = False) -> bytes:
        """The message: one ``bytes.join``, so each bulk buffer is copied once. ``pad``: 0-3 zero
        bytes more, to a multiple of 4 as DDS wants, inside the same allocation."""
        parts: list[bytes | memoryview] = list(self.parts)
        total = self.pos
        for view in bulk:
            parts.append(view)
            total += view.nbytes
        if pad:
            parts.append(_PAD[-(total + len(CDR_LE_HEADER)) % 4])
        return b"".join(parts)


class CdrReader:
    """Reads a classic-CDR message of either byte order; every read is bounds-checked."""

    __slots__ = ("body", "pos", "end", "order")

    def __init__(self, data: Buffer) -> None:
        view = as_byte_view(data)
        if view.nbytes < 4:
            raise CdrError("buffer shorter than the encapsulation header")
        ident = bytes(view[:2])
        if ident not in _BYTE_ORDERS:
            raise CdrError(f"unsupported encapsulation {ident.hex()} (want classic CDR 0000/0001)")
        self.order = _BYTE_ORDERS[ident]
        self.body = view[4:]
        self.pos = 0
        self.end = self.body.nbytes

    def take(self, count: int) -> memoryview:
        if count < 0 or self.pos + count > self.end:
            raise CdrError(f"truncated: need {count} bytes at offset {self.pos}, have {self.end - self.pos}")
        view = self.body[self.pos : self.pos + count]
        self.pos += count
        return view

    def align(self, size: int) -> None:
        self.pos += -self.pos % size
        if self.pos > self.end:
            raise CdrError("truncated while aligning")

    def unpack(self, fmt: str, size: int, align: int) -> tuple[Any, ...]:
        self.align(align)
        return struct.unpack(self.order + fmt, self.take(size))

    def u8(self) -> int:
        return int(self.unpack("B", 1, 1)[0])

    def u32(self) -> int:
        return int(self.unpack("I", 4, 4)[0])

    def string(self) -> str:
        length = self.u32()
        if length == 0:
            raise CdrError("string length 0 (must include the NUL terminator)")
        raw = self.take(length)
        if raw[length - 1] != 0:
            raise CdrError("string is not NUL-terminated")
        try:
            return bytes(raw[: length - 1]).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise CdrError(f"string is not valid UTF-8: {exc}") from None

    def octets(self) -> memoryview:
        """A ``sequence<uint8>``, as a view into the input (no copy)."""
        return self.take(self.u32())

    def f64s(self, count: int) -> tuple[float, ...]:
        if count == 0:
            return ()
        if count > (self.end - self.pos) // 8 + 1:  # before struct builds a huge format
            raise CdrError(f"sequence length {count} exceeds the remaining data")
        return tuple(self.unpack(f"{count}d", 8 * count, 8))
