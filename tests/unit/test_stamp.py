"""The frame-id stamp in the first and last pixel rows (fxis_shm.formats.stamp)."""

from __future__ import annotations

import numpy as np
import pytest

from fxis_shm.formats.stamp import CHECKED_BYTES, STAMP_BYTES, read_stamp, write_stamp

LAYOUTS = [
    pytest.param((48, 64), np.uint8, id="mono8"),
    pytest.param((48, 64, 3), np.uint8, id="bgr8"),
    pytest.param((48, 64), np.uint16, id="mono16"),
    pytest.param((1, 16), np.uint8, id="one-row"),
    pytest.param((2, 8), np.uint16, id="exactly-16-bytes-a-row"),
    pytest.param((3, 6, 3), np.uint8, id="bgr8-18-bytes-a-row"),
]
IDS = [0, 1, 255, 256, 2**32 + 5, 2**40, 2**63, 2**64 - 1]


def patterned(shape, dtype) -> np.ndarray:
    """A non-uniform image, so that a stamp cannot pass by accident."""
    return (np.arange(int(np.prod(shape))) * 7 % 251).astype(dtype).reshape(shape)


def stamped(shape, dtype, frame_id) -> np.ndarray:
    image = patterned(shape, dtype)
    write_stamp(image, frame_id)
    return image


@pytest.mark.parametrize("shape, dtype", LAYOUTS)
@pytest.mark.parametrize("frame_id", IDS)
def test_a_stamp_reads_back(shape, dtype, frame_id):
    assert read_stamp(stamped(shape, dtype, frame_id)) == frame_id


@pytest.mark.parametrize("shape, dtype", LAYOUTS)
def test_only_the_first_stamp_bytes_of_the_first_and_last_rows_change(shape, dtype):
    before = patterned(shape, dtype)
    after = stamped(shape, dtype, 2**40)
    changed = (before != after).reshape(shape[0], -1)
    untouched = np.ones_like(changed)
    row_bytes = int(np.prod(shape[1:])) * np.dtype(dtype).itemsize
    stamp = CHECKED_BYTES if row_bytes >= CHECKED_BYTES else STAMP_BYTES  # with its check where it fits
    per_row = stamp // np.dtype(dtype).itemsize  # elements of a row that hold the stamp
    untouched[[0, -1], :per_row] = False
    assert not changed[untouched].any()


def test_restamping_replaces_the_id():
    image = stamped((8, 32), np.uint8, 1)
    write_stamp(image, 2)
    assert read_stamp(image) == 2


@pytest.mark.parametrize("shape, dtype", [s for s in LAYOUTS if s.values[0][0] > 1])
@pytest.mark.parametrize("split", ["top-row-only", "half", "all-but-bottom-row"])
def test_a_torn_image_does_not_read_as_either_frame(shape, dtype, split):
    older, newer = stamped(shape, dtype, 41), stamped(shape, dtype, 42)
    rows = {"top-row-only": 1, "half": shape[0] // 2, "all-but-bottom-row": shape[0] - 1}[split]
    torn = np.concatenate([older[:rows], newer[rows:]])
    assert read_stamp(torn) not in (41, 42)


@pytest.mark.parametrize(
    "image",
    [
        pytest.param(np.zeros((8, 32), np.uint8), id="never-stamped"),
        pytest.param(np.full((8, 32), 255, np.uint8), id="all-ones"),
        pytest.param(np.zeros((8, 15), np.uint8), id="too-narrow"),
        pytest.param(np.zeros(64, np.uint8), id="one-dimensional"),
    ],
)
def test_an_image_without_a_valid_stamp_reads_as_none(image):
    assert read_stamp(image) is None


def test_a_corrupted_complement_reads_as_none():
    image = stamped((8, 32), np.uint8, 1234)
    image[[0, -1], STAMP_BYTES - 1] ^= 1  # both rows still agree, but not with the id
    assert read_stamp(image) is None


def test_a_stamp_in_a_non_contiguous_view_is_not_read():
    # every other column: the row's bytes are not the bytes the stamp was written to
    image = stamped((8, 64), np.uint8, 77)[:, ::2]
    assert read_stamp(image) is None


@pytest.mark.parametrize(
    "shape, dtype",
    [((8, 15), np.uint8), ((8, 7), np.uint16), ((8, 5, 3), np.uint8), ((0, 64), np.uint8)],
)
def test_an_image_too_small_for_a_stamp_is_refused(shape, dtype):
    image = np.zeros(shape, dtype)
    with pytest.raises(ValueError):
        write_stamp(image, 1)
    assert not image.any()


@pytest.mark.parametrize("shape", [(240, 320), (1024, 1360), (1024, 1360, 3)])
@pytest.mark.parametrize("quality", [75, 90])
def test_the_block_stamp_survives_jpeg(shape, quality):
    from fxis_shm.wire import encoding as codec

    image = np.random.default_rng(1).integers(0, 256, shape, dtype=np.uint8)
    write_stamp(image, 0x1_2345_6789)
    back = codec.decode(codec.encode(image, "jpeg", quality), "jpeg", image.shape, "uint8")
    assert read_stamp(back) == 0x2345_6789  # after lossy compression: the low 32 bits


def test_a_torn_image_reads_as_none_even_by_its_blocks():
    image = np.zeros((240, 320), np.uint8)
    write_stamp(image, 7)
    other = np.zeros_like(image)
    write_stamp(other, 8)
    image[120:] = other[120:]  # the bottom half from another frame
    image[0, 0] ^= 1  # and the byte stamp spoiled, as compression would
    assert read_stamp(image) is None


def synthetic_frames(width: int, height: int, pixel_format: str, ids):
    """The synthetic camera's own frames (its board, moving, and its stamp), by id."""
    from fxis_shm.core import timebase
    from fxis_shm.service.camerakinds import camera_options
    from fxis_shm.workers.backends.synthetic import SyntheticCamera

    options = camera_options("a", "synthetic", {"width": width, "height": height, "pixel_format": pixel_format})
    camera = SyntheticCamera("a", options, timebase.now())
    camera.open()
    for frame_id in ids:
        yield frame_id, camera._render(frame_id)


@pytest.mark.parametrize(
    "width, height, pixel_format, ids, qualities",
    [
        # 160x120 mono8 at quality 90 read frames 467, 2462, 2573 and 2785 as wrong ids before the check
        (160, 120, "mono8", range(3000), [90]),
        (320, 240, "bgr8", range(0, 3000, 7), [50, 75, 90]),
        (160, 120, "mono8", range(2**32 - 200, 2**32 + 200), [60]),  # ids past 32 bits: their low bits
    ],
)
def test_many_jpeg_frames_never_read_as_a_wrong_id(width, height, pixel_format, ids, qualities):
    import cv2

    read = wrong = 0
    for frame_id, image in synthetic_frames(width, height, pixel_format, ids):
        for quality in qualities:
            _, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
            got = read_stamp(cv2.imdecode(data, cv2.IMREAD_UNCHANGED))
            read += got is not None
            wrong += got not in (None, frame_id & 0xFFFFFFFF)
    assert wrong == 0
    assert read >= 0.99 * len(ids) * len(qualities)  # and the stamp still serves: nearly all read


def test_noise_and_jpeg_of_noise_never_read_as_a_stamp():
    import cv2

    rng = np.random.default_rng(5)
    for _ in range(300):
        image = rng.integers(0, 256, (120, 160), dtype=np.uint8)
        assert read_stamp(image) is None
        _, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 90])
        assert read_stamp(cv2.imdecode(data, cv2.IMREAD_UNCHANGED)) is None


def test_a_stamp_whose_check_is_spoiled_reads_as_none():
    image = stamped((240, 320), np.uint8, 1234)
    image[[0, -1], 16] ^= 1  # the CRC's first byte, in both rows alike
    assert read_stamp(image) == 1234  # the bytes no longer read; the blocks still say it
    per_row = 320 // 8
    check_block = 32  # the first check bit's block: flip it and its complement in both bands
    for top in (8, 240 - 8 - (-(-96 // per_row)) * 8):
        for block in (check_block, check_block + 48):
            row, col = divmod(block, per_row)
            cell = image[top + row * 8 : top + row * 8 + 8, col * 8 : col * 8 + 8]
            cell[...] = 255 - cell
    assert read_stamp(image) is None
