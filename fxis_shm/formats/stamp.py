"""The frame-id stamp that the synthetic camera writes into its pixels.

The id is written twice, into the first and the last row of the image: eight
bytes of the id (little-endian uint64) followed by eight bytes of its bitwise
complement. ``read_stamp`` returns the id only if both rows carry the same
valid stamp, so an image assembled from two different frames (a torn copy)
reads as ``None`` or as a different id, never as the id in its metadata.

Works for any dtype and channel count as long as a row holds 16 bytes.

Lossy compression (JPEG) changes those bytes, so 8-bit images large enough also carry
the id as black and white 8x8 blocks, JPEG's own block size, in a band near the top and
again near the bottom (32 bits of the id, then their complement): ``read_stamp`` falls
back to them when the bytes do not read, and a torn image still reads as None.
"""

from __future__ import annotations

import numpy as np

from fxis_shm.errors import InvalidArgument

STAMP_BYTES = 16


def _row_bytes(image: np.ndarray, row: int) -> np.ndarray:
    row_bytes: np.ndarray = image[row].reshape(-1).view(np.uint8)
    return row_bytes


def _encode(frame_id: int) -> np.ndarray:
    ident = np.array([frame_id & 0xFFFFFFFFFFFFFFFF], dtype="<u8")
    return np.concatenate([ident.view(np.uint8), (~ident).view(np.uint8)])


BLOCK = 8  # px: JPEG compresses 8x8 blocks, so a block of one value survives it
BLOCK_BITS = 64  # 32 bits of the id and their complement
MARGIN = 8  # px between the byte stamp's row and a block band


def _bands(shape: tuple[int, ...]) -> tuple[int, int, int] | None:
    """(blocks per band row, band height, bottom band's first row), or None if the image is too small."""
    per_row = shape[1] // BLOCK
    if per_row < 1:
        return None
    height = -(-BLOCK_BITS // per_row) * BLOCK
    bottom = shape[0] - MARGIN - height
    return (per_row, height, bottom) if bottom >= 2 * MARGIN + height else None


def _block_bits(frame_id: int) -> np.ndarray:
    ident = frame_id & 0xFFFFFFFF
    bits = [(ident >> i) & 1 for i in range(32)]
    return np.array(bits + [1 - b for b in bits], dtype=np.uint8)


def _write_blocks(image: np.ndarray, frame_id: int) -> None:
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


def _read_blocks(image: np.ndarray) -> int | None:
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
        read.append((centres.reshape(-1)[:BLOCK_BITS] > 127).astype(np.uint8))
    if not np.array_equal(read[0], read[1]) or not np.all(read[0][:32] != read[0][32:]):
        return None
    return int(sum(int(b) << i for i, b in enumerate(read[0][:32])))


def write_stamp(image: np.ndarray, frame_id: int) -> None:
    """Stamp ``frame_id`` into the first and the last row of ``image`` (in place), and, for an
    8-bit image large enough, as blocks that survive JPEG."""
    if image.ndim < 1 or image.shape[0] < 1:
        raise InvalidArgument(f"an image of shape {image.shape} has no row to hold a stamp")
    if image[0].nbytes < STAMP_BYTES:
        raise InvalidArgument(f"image rows of {image[0].nbytes} bytes cannot hold a stamp")
    code = _encode(frame_id)
    for row in (0, image.shape[0] - 1):
        _row_bytes(image, row)[:STAMP_BYTES] = code
    if image.ndim >= 2:
        _write_blocks(image, frame_id)


def read_stamp(image: np.ndarray) -> int | None:
    """The frame id stamped into ``image``, or None if there is no consistent stamp. After
    lossy compression only the blocks read: then the id's low 32 bits."""
    if image.ndim < 2 or image[0].nbytes < STAMP_BYTES or not image[0].flags.c_contiguous:
        return None
    first = _row_bytes(image, 0)[:STAMP_BYTES]
    last = _row_bytes(image, image.shape[0] - 1)[:STAMP_BYTES]
    ident = first[:8].view("<u8")[0]
    if np.array_equal(first, last) and first[8:].view("<u8")[0] == ~ident:
        return int(ident)
    return _read_blocks(image)
