"""Image encodings for everything that leaves the host's memory: network replies and streams,
the dashboard, recordings and Foxglove. One place encodes and decodes, so every part of the
product gives the same bytes for the same frame.

Pure: arrays in, bytes out (and back). ``raw`` is the frame's bytes as they are; ``jpeg`` takes
mono8 and bgr8 frames; ``png`` is lossless and also takes 16-bit mono.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from fxis_shm.errors import ProtocolError

RAW, JPEG, PNG = "raw", "jpeg", "png"
ENCODINGS = (RAW, JPEG, PNG)
DEFAULT_JPEG_QUALITY = 90
MEDIA_TYPES = {JPEG: "image/jpeg", PNG: "image/png"}


def check(encoding: str, quality: int = DEFAULT_JPEG_QUALITY) -> tuple[str, int]:
    """The encoding and quality as given, or ``ProtocolError`` saying what is wrong."""
    if encoding not in ENCODINGS:
        raise ProtocolError(f"unknown encoding {encoding!r}: use one of {', '.join(ENCODINGS)}")
    if isinstance(quality, bool) or not isinstance(quality, int) or not 1 <= quality <= 100:
        raise ProtocolError(f"JPEG quality must be an integer from 1 to 100, got {quality!r}")
    return encoding, quality


def _check_encodable(image: NDArray[Any], encoding: str) -> None:
    channels = 1 if image.ndim == 2 else image.shape[2]
    if channels not in (1, 3):
        raise ProtocolError(f"{encoding} takes mono or 3-channel frames, not {channels} channels")
    allowed = ("uint8",) if encoding == JPEG else ("uint8", "uint16")
    if image.dtype.name not in allowed:
        raise ProtocolError(f"{encoding} takes {' or '.join(allowed)} frames, not {image.dtype.name}")


def encode(image: NDArray[Any], encoding: str, quality: int = DEFAULT_JPEG_QUALITY) -> bytes:
    """The frame's bytes in ``encoding`` (3-channel frames are taken as BGR)."""
    check(encoding, quality)
    if encoding == RAW:
        return np.ascontiguousarray(image).tobytes()
    _check_encodable(image, encoding)
    import cv2  # here: a process that never encodes (a camera worker, `fxis run`) is spared its import

    params = [cv2.IMWRITE_JPEG_QUALITY, quality] if encoding == JPEG else [cv2.IMWRITE_PNG_COMPRESSION, 1]
    ok, data = cv2.imencode("." + encoding, image, params)
    if not ok:
        raise ProtocolError(f"could not encode a {image.shape} {image.dtype.name} frame as {encoding}")
    return data.tobytes()


def decode(data: bytes | memoryview, encoding: str, shape: tuple[int, ...] | None, dtype: str | None) -> NDArray[Any]:
    """The frame back from its bytes, with the ``shape`` and ``dtype`` it was sent with
    (None for both: as the JPEG or PNG data says, for a file whose frames come unannounced)."""
    if encoding == RAW:
        image = np.frombuffer(data, dtype=dtype)
    else:
        import cv2

        decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if decoded is None:
            raise ProtocolError(f"the {encoding} data of a frame could not be decoded")
        image = np.asarray(decoded)
        if shape is None and dtype is None:
            return image
    if shape is None or image.size != int(np.prod(shape)) or image.dtype.name != dtype:
        raise ProtocolError(f"a {encoding} frame decoded to {image.shape} {image.dtype.name}, expected {shape} {dtype}")
    return image.reshape(shape)
