"""The ROS 2 messages a camera bridge sends and reads, as the bytes ROS puts on the wire.

Encoders and decoders of XCDR1 (classic CDR, ``fxis_shm.formats.cdrstream``) for
``std_msgs/msg/Header``, ``std_msgs/msg/String``, ``sensor_msgs/msg/Image``,
``sensor_msgs/msg/CompressedImage`` and ``sensor_msgs/msg/CameraInfo`` (with
``sensor_msgs/msg/RegionOfInterest``), ``diagnostic_msgs/msg/DiagnosticArray`` and
``rmw_dds_common/msg/ParticipantEntitiesInfo``. Their bytes are exactly what rmw puts on the
wire and what rosbags' ``Typestore.serialize_cdr`` makes (tests/unit/test_cdr.py compares them, for
Humble and Jazzy). Every struct is ``final``: no DHEADER or EMHEADER, no padding after the
last member.

Why by hand: cyclonedds' own serializer packs ``sequence<uint8>`` element by element (34 ms
for a 1360x1024 mono8 frame). Here a pixel message is a small prefix made with :mod:`struct`
and one ``bytes.join`` with the pixels: one memcpy, no per-element work.

Pure (numpy and the standard library). Decoders accept either byte order, ignore trailing
padding and raise only :class:`CdrError`: safe on untrusted network input.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from numpy.typing import NDArray

from fxis_shm.formats.cdrstream import (
    CDR_LE_HEADER as CDR_LE_HEADER,
    Buffer as Buffer,
    CdrError as CdrError,
    CdrReader,
    CdrWriter,
    as_byte_view,
    pad4 as pad4,
)

NS_PER_SECOND = 1_000_000_000


def stamp(ns: int) -> tuple[int, int]:
    """A time in integer nanoseconds as ROS's ``builtin_interfaces/Time`` (sec, nanosec).

    Floor division, so ``nanosec`` is always in [0, 1e9): -1 ns is (-1, 999_999_999), as
    rclcpp's ``Time`` gives it. A ``sec`` outside int32 is refused when the message is encoded.
    """
    sec, nanosec = divmod(ns, NS_PER_SECOND)
    return sec, nanosec


@dataclass(frozen=True)
class Header:
    """``std_msgs/msg/Header``: ``builtin_interfaces/Time stamp`` and ``string frame_id``."""

    sec: int = 0
    nanosec: int = 0
    frame_id: str = ""

    @classmethod
    def at(cls, ns: int, frame_id: str = "") -> Header:
        """The header of a message stamped ``ns`` nanoseconds (since the epoch of its clock)."""
        sec, nanosec = stamp(ns)
        return cls(sec, nanosec, frame_id)

    @property
    def stamp_ns(self) -> int:
        """The stamp in integer nanoseconds: the inverse of :meth:`at`."""
        return self.sec * NS_PER_SECOND + self.nanosec


@dataclass(frozen=True)
class RegionOfInterest:
    """``sensor_msgs/msg/RegionOfInterest``."""

    x_offset: int = 0
    y_offset: int = 0
    height: int = 0
    width: int = 0
    do_rectify: bool = False


@dataclass(frozen=True)
class Image:
    """A decoded ``sensor_msgs/msg/Image``; ``data`` is a view into the decoded buffer (no copy)."""

    header: Header
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: memoryview


@dataclass(frozen=True)
class CompressedImage:
    """A decoded ``sensor_msgs/msg/CompressedImage``; ``data`` is a view (no copy)."""

    header: Header
    format: str
    data: memoryview


@dataclass(frozen=True)
class CameraInfo:
    """``sensor_msgs/msg/CameraInfo``, both to encode and as the decoder's result."""

    header: Header = field(default_factory=Header)
    height: int = 0
    width: int = 0
    distortion_model: str = ""
    d: Sequence[float] = ()
    k: Sequence[float] = (0.0,) * 9
    r: Sequence[float] = (0.0,) * 9
    p: Sequence[float] = (0.0,) * 12
    binning_x: int = 0
    binning_y: int = 0
    roi: RegionOfInterest = field(default_factory=RegionOfInterest)


@dataclass(frozen=True)
class DiagnosticStatus:
    """``diagnostic_msgs/msg/DiagnosticStatus``: level OK 0, WARN 1, ERROR 2, STALE 3."""

    level: int
    name: str
    message: str = ""
    hardware_id: str = ""
    values: Sequence[tuple[str, str]] = ()  # diagnostic_msgs/msg/KeyValue


# ------------------------------------------------------------------------------------ encoding


def _write_header(writer: CdrWriter, header: Header) -> None:
    writer.pack("<iI", 8, 4, header.sec, header.nanosec)
    writer.string(header.frame_id)


def encode_header(header: Header) -> bytes:
    """``std_msgs/msg/Header``."""
    writer = CdrWriter()
    _write_header(writer, header)
    return writer.finish()


def encode_string(data: str) -> bytes:
    """``std_msgs/msg/String``."""
    writer = CdrWriter()
    writer.string(data)
    return writer.finish()


def encode_image(
    header: Header,
    *,
    height: int,
    width: int,
    encoding: str,
    step: int,
    data: Buffer,
    is_bigendian: int = 0,
    pad: bool = False,
) -> bytes:
    """``sensor_msgs/msg/Image`` with ``data`` taken as it is from a buffer: one memcpy of it.

    ``pad=True`` appends 0-3 zero bytes, to the multiple of 4 DDS wants, in the same allocation.
    """
    pixels = as_byte_view(data)
    writer = CdrWriter()
    _write_header(writer, header)
    writer.u32(height)
    writer.u32(width)
    writer.string(encoding)
    writer.u8(is_bigendian)
    writer.u32(step)
    writer.u32(pixels.nbytes)  # sequence<uint8>: the count, then bytes that need no alignment
    return writer.finish(pixels, pad=pad)


def encode_image_array(header: Header, array: NDArray[Any], encoding: str, *, pad: bool = False) -> bytes:
    """A ``(H, W)`` or ``(H, W, C)`` array as ``sensor_msgs/msg/Image`` in ROS ``encoding``.

    ``step`` is ``W * C * itemsize`` (a strided array is made contiguous first) and
    ``is_bigendian`` follows the dtype's byte order.
    """
    if array.ndim not in (2, 3):
        raise CdrError(f"an image array must be 2-D or 3-D, got shape {array.shape}")
    height, width = int(array.shape[0]), int(array.shape[1])
    channels = int(array.shape[2]) if array.ndim == 3 else 1
    order = array.dtype.byteorder
    big = order == ">" or (order == "=" and sys.byteorder == "big")
    return encode_image(
        header,
        height=height,
        width=width,
        encoding=encoding,
        step=width * channels * array.dtype.itemsize,
        data=array,
        is_bigendian=int(big and array.dtype.itemsize > 1),
        pad=pad,
    )


def encode_compressed_image(header: Header, format: str, data: Buffer, *, pad: bool = False) -> bytes:
    """``sensor_msgs/msg/CompressedImage``: one memcpy of ``data``."""
    payload = as_byte_view(data)
    writer = CdrWriter()
    _write_header(writer, header)
    writer.string(format)
    writer.u32(payload.nbytes)
    return writer.finish(payload, pad=pad)


def encode_camera_info(msg: CameraInfo, *, pad: bool = False) -> bytes:
    """``sensor_msgs/msg/CameraInfo`` (``d`` a float64 sequence, ``k``, ``r``, ``p`` arrays)."""
    writer = CdrWriter()
    _write_header(writer, msg.header)
    writer.u32(msg.height)
    writer.u32(msg.width)
    writer.string(msg.distortion_model)
    d = [float(x) for x in msg.d]
    writer.u32(len(d))
    if d:  # an empty sequence<double> takes no alignment
        writer.f64_array(d, len(d), "d")
    writer.f64_array([float(x) for x in msg.k], 9, "k")
    writer.f64_array([float(x) for x in msg.r], 9, "r")
    writer.f64_array([float(x) for x in msg.p], 12, "p")
    writer.u32(msg.binning_x)
    writer.u32(msg.binning_y)
    roi = msg.roi
    writer.pack("<4I", 16, 4, roi.x_offset, roi.y_offset, roi.height, roi.width)
    writer.u8(1 if roi.do_rectify else 0)
    return writer.finish(pad=pad)


def encode_diagnostic_array(header: Header, statuses: Sequence[DiagnosticStatus], *, pad: bool = False) -> bytes:
    """``diagnostic_msgs/msg/DiagnosticArray``."""
    writer = CdrWriter()
    _write_header(writer, header)
    writer.u32(len(statuses))
    for status in statuses:
        writer.u8(status.level)
        for text in (status.name, status.message, status.hardware_id):
            writer.string(text)
        writer.u32(len(status.values))
        for key, value in status.values:
            writer.string(key)
            writer.string(value)
    return writer.finish(pad=pad)


GID_SIZE = 16  # rmw_dds_common/msg/Gid: char[16] since Iron (Humble's was 24 bytes)


@dataclass(frozen=True)
class NodeEntities:
    """``rmw_dds_common/msg/NodeEntitiesInfo``: a node and the GUIDs (16 bytes) of its endpoints."""

    namespace: str
    name: str
    readers: Sequence[bytes] = ()
    writers: Sequence[bytes] = ()


def encode_participant_entities_info(gid: bytes, nodes: Sequence[NodeEntities], *, pad: bool = False) -> bytes:
    """``rmw_dds_common/msg/ParticipantEntitiesInfo`` (Iron and later), what every rmw publishes on
    ``ros_discovery_info`` so that other nodes know which endpoints belong to which node."""
    writer = CdrWriter()

    def gid_of(value: bytes) -> None:
        if len(value) != GID_SIZE:
            raise CdrError(f"a gid is {GID_SIZE} bytes, got {len(value)}")
        writer.raw(bytes(value))

    def gids(values: Sequence[bytes]) -> None:
        writer.u32(len(values))
        for value in values:
            gid_of(value)

    gid_of(gid)
    writer.u32(len(nodes))
    for node in nodes:
        writer.string(node.namespace)
        writer.string(node.name)
        gids(node.readers)
        gids(node.writers)
    return writer.finish(pad=pad)


# ------------------------------------------------------------------------------------ decoding


def _read_header(reader: CdrReader) -> Header:
    sec, nanosec = reader.unpack("iI", 8, 4)
    return Header(sec, nanosec, reader.string())


def decode_header(data: Buffer) -> Header:
    """``std_msgs/msg/Header`` (a request, from the network)."""
    return _read_header(CdrReader(data))


def decode_string(data: Buffer) -> str:
    """``std_msgs/msg/String``."""
    return CdrReader(data).string()


def decode_image(data: Buffer) -> Image:
    """``sensor_msgs/msg/Image``; its ``data`` is a view into ``data``."""
    reader = CdrReader(data)
    header = _read_header(reader)
    height, width = reader.u32(), reader.u32()
    encoding = reader.string()
    is_bigendian = reader.u8()
    step = reader.u32()
    return Image(header, height, width, encoding, is_bigendian, step, reader.octets())


def decode_compressed_image(data: Buffer) -> CompressedImage:
    """``sensor_msgs/msg/CompressedImage``; its ``data`` is a view into ``data``."""
    reader = CdrReader(data)
    header = _read_header(reader)
    return CompressedImage(header, reader.string(), reader.octets())


def decode_camera_info(data: Buffer) -> CameraInfo:
    """``sensor_msgs/msg/CameraInfo``."""
    reader = CdrReader(data)
    header = _read_header(reader)
    height, width = reader.u32(), reader.u32()
    model = reader.string()
    d = reader.f64s(reader.u32())
    k, r, p = reader.f64s(9), reader.f64s(9), reader.f64s(12)
    binning_x, binning_y = reader.u32(), reader.u32()
    x_offset, y_offset, roi_height, roi_width = reader.unpack("4I", 16, 4)
    roi = RegionOfInterest(x_offset, y_offset, roi_height, roi_width, bool(reader.u8()))
    return CameraInfo(header, height, width, model, d, k, r, p, binning_x, binning_y, roi)
