"""The frame-id stamp that the synthetic camera writes into its pixels.

The id is written twice, into the first and the last row of the image: eight bytes of the
id (little-endian uint64) followed by eight bytes of its bitwise complement, and, where a
row holds 24 bytes, a check: four bytes of the CRC-32 of the id's eight and four of that
CRC's complement. ``read_stamp`` returns the id only if both rows carry the same valid
stamp, so an image assembled from two different frames (a torn copy) reads as ``None`` or
as a different id, never as the id in its metadata; and bytes that lossy compression
happened to leave looking like an id and its complement (1 JPEG in 600 did) fail the check
and read as None. (Clients that read only the first 16 bytes, docs/protocol.md section 17,
read raw frames as before.)

Works for any dtype and channel count as long as a row holds 16 bytes.

Lossy compression (JPEG) changes those bytes, so 8-bit images large enough also carry the
id's low 32 bits as black and white 8x8 blocks, JPEG's own block size, with a 16-bit check
(of the CRC-32 of those bits), in a band near the top and again near the bottom: each bit
as a block and, further on, its complement. A bit reads as the sign of the difference
between the two, in each band; both bands must agree on every bit, each clearly, and the
check must hold: ``read_stamp`` falls back to them when the bytes do not read, a torn image
still reads as None, and a misread is caught by the check, not returned (the redundancy,
two copies, complements and a check, is what a lossy video codec will need too).
"""

from __future__ import annotations

import zlib
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fxis_shm.errors import InvalidArgument

STAMP_BYTES = 16


def _row_bytes(image: NDArray[Any], row: int) -> NDArray[Any]:
    row_bytes: NDArray[Any] = image[row].reshape(-1).view(np.uint8)
    return row_bytes


CHECKED_BYTES = 24  # a row this long also holds the check


def _encode(frame_id: int, row_bytes: int) -> NDArray[Any]:
    """The stamp for a row of ``row_bytes``: the id and its complement, then the check if it fits."""
    ident = (frame_id & 0xFFFFFFFFFFFFFFFF).to_bytes(8, "little")
    code = ident + bytes(b ^ 0xFF for b in ident)
    if row_bytes >= CHECKED_BYTES:
        crc = zlib.crc32(ident)
        code += crc.to_bytes(4, "little") + (crc ^ 0xFFFFFFFF).to_bytes(4, "little")
    return np.frombuffer(code, np.uint8)


BLOCK = 8  # px: JPEG compresses 8x8 blocks, so a block of one value survives it
ID_BITS, CHECK_BITS = 32, 16  # the id's low 32 bits and a 16-bit check of them
BLOCK_BITS = 2 * (ID_BITS + CHECK_BITS)  # each bit and, further on, its complement
MARGIN = 8  # px between the byte stamp's row and a block band
CLEAR = 40  # of 255: how much a bit's block must differ from its complement's to be read


def _bands(shape: tuple[int, ...]) -> tuple[int, int, int] | None:
    """(blocks per band row, band height, bottom band's first row), or None if the image is too small."""
    per_row = shape[1] // BLOCK
    if per_row < 1:
        return None
    height = -(-BLOCK_BITS // per_row) * BLOCK
    bottom = shape[0] - MARGIN - height
    return (per_row, height, bottom) if bottom >= 2 * MARGIN + height else None


def _check(ident: int) -> int:
    """The 16-bit check of a 32-bit id: the low half of its CRC-32."""
    return zlib.crc32(ident.to_bytes(4, "little")) & 0xFFFF


def _block_bits(frame_id: int) -> NDArray[Any]:
    ident = frame_id & 0xFFFFFFFF
    word = ident | _check(ident) << ID_BITS
    bits = [(word >> i) & 1 for i in range(ID_BITS + CHECK_BITS)]
    return np.array(bits + [1 - b for b in bits], dtype=np.uint8)


def _write_blocks(image: NDArray[Any], frame_id: int) -> None:
    bands = _bands(image.shape)
    if bands is None or image.dtype != np.uint8:
        return
    per_row, height, bottom = bands
    grid = np.zeros(height // BLOCK * per_row, np.uint8)
    grid[:BLOCK_BITS] = _block_bits(frame_id) * 255
    band = np.repeat(np.repeat(grid.reshape(-1, per_row), BLOCK, 0), BLOCK, 1)
    if image.ndim == 3:
        band = band[..., None]
    for top in (MARGIN, bottom):
        image[top : top + height, : per_row * BLOCK] = band


def _read_blocks(image: NDArray[Any]) -> int | None:
    bands = _bands(image.shape)
    if bands is None or image.dtype != np.uint8:
        return None
    per_row, height, bottom = bands
    read = []
    for top in (MARGIN, bottom):
        area = image[top : top + height, : per_row * BLOCK].astype(np.int32)
        if area.ndim == 3:
            area = area.mean(axis=2)
        # each block's centre, away from its edges where compression rings
        centres = area.reshape(height // BLOCK, BLOCK, per_row, BLOCK)[:, 2:6, :, 2:6].mean(axis=(1, 3))
        values = centres.reshape(-1)[:BLOCK_BITS]
        half = BLOCK_BITS // 2
        read.append(values[:half] - values[half:])  # a bit's block less its complement's
    top, bottom = read
    if np.any(np.abs(top) < CLEAR) or np.any(np.abs(bottom) < CLEAR) or np.any((top > 0) != (bottom > 0)):
        return None  # a bit not clear, or the bands disagree (a torn image)
    word = sum(1 << i for i, d in enumerate(top) if d > 0)
    ident = word & 0xFFFFFFFF
    return ident if word >> ID_BITS == _check(ident) else None


def write_stamp(image: NDArray[Any], frame_id: int) -> None:
    """Stamp ``frame_id`` into the first and the last row of ``image`` (in place), and, for an
    8-bit image large enough, as blocks that survive JPEG."""
    if image.ndim < 1 or image.shape[0] < 1:
        raise InvalidArgument(f"an image of shape {image.shape} has no row to hold a stamp")
    if image[0].nbytes < STAMP_BYTES:
        raise InvalidArgument(f"image rows of {image[0].nbytes} bytes cannot hold a stamp")
    code = _encode(frame_id, image[0].nbytes)
    for row in (0, image.shape[0] - 1):
        _row_bytes(image, row)[: len(code)] = code
    if image.ndim >= 2:
        _write_blocks(image, frame_id)


def read_stamp(image: NDArray[Any]) -> int | None:
    """The frame id stamped into ``image``, or None if there is no consistent stamp. After
    lossy compression only the blocks read: then the id's low 32 bits."""
    if image.ndim < 2 or image[0].nbytes < STAMP_BYTES or not image[0].flags.c_contiguous:
        return None
    size = CHECKED_BYTES if image[0].nbytes >= CHECKED_BYTES else STAMP_BYTES
    first = _row_bytes(image, 0)[:size]
    last = _row_bytes(image, image.shape[0] - 1)[:size]
    ident = int(first[:8].view("<u8")[0])
    if np.array_equal(first, last) and np.array_equal(first, _encode(ident, size)):
        return ident
    return _read_blocks(image)
