"""The frame-id stamp that the synthetic camera writes into its pixels.

The id is written twice, into the first and the last row of the image: eight
bytes of the id (little-endian uint64) followed by eight bytes of its bitwise
complement. ``read_stamp`` returns the id only if both rows carry the same
valid stamp, so an image assembled from two different frames (a torn copy)
reads as ``None`` or as a different id, never as the id in its metadata.

Works for any dtype and channel count as long as a row holds 16 bytes.
"""
from __future__ import annotations

import numpy as np

from .errors import InvalidArgument

STAMP_BYTES = 16


def _row_bytes(image: np.ndarray, row: int) -> np.ndarray:
    row_bytes: np.ndarray = image[row].reshape(-1).view(np.uint8)
    return row_bytes


def _encode(frame_id: int) -> np.ndarray:
    ident = np.array([frame_id & 0xFFFFFFFFFFFFFFFF], dtype="<u8")
    return np.concatenate([ident.view(np.uint8), (~ident).view(np.uint8)])


def write_stamp(image: np.ndarray, frame_id: int) -> None:
    """Stamp ``frame_id`` into the first and the last row of ``image`` (in place)."""
    if image.ndim < 1 or image.shape[0] < 1:
        raise InvalidArgument(f"an image of shape {image.shape} has no row to hold a stamp")
    if image[0].nbytes < STAMP_BYTES:
        raise InvalidArgument(f"image rows of {image[0].nbytes} bytes cannot hold a stamp")
    code = _encode(frame_id)
    for row in (0, image.shape[0] - 1):
        _row_bytes(image, row)[:STAMP_BYTES] = code


def read_stamp(image: np.ndarray) -> int | None:
    """The frame id stamped into ``image``, or None if there is no consistent stamp."""
    if image.ndim < 2 or image[0].nbytes < STAMP_BYTES or not image[0].flags.c_contiguous:
        return None
    first = _row_bytes(image, 0)[:STAMP_BYTES]
    last = _row_bytes(image, image.shape[0] - 1)[:STAMP_BYTES]
    if not np.array_equal(first, last):
        return None
    ident = first[:8].view("<u8")[0]
    if first[8:].view("<u8")[0] != ~ident:
        return None
    return int(ident)
