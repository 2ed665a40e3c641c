import numpy as np
import pytest

from fxis_shm.errors import ProtocolError
from fxis_shm.wire import encoding


def _image(shape, dtype="uint8"):
    rng = np.random.default_rng(0)
    top = 255 if dtype == "uint8" else 4095
    return rng.integers(0, top, size=shape).astype(dtype)


@pytest.mark.parametrize("shape,dtype", [((48, 64), "uint8"), ((48, 64, 3), "uint8"), ((48, 64), "uint16")])
@pytest.mark.parametrize("name", ["raw", "png"])
def test_lossless_encodings_give_the_frame_back(shape, dtype, name):
    image = _image(shape, dtype)
    data = encoding.encode(image, name)
    assert np.array_equal(encoding.decode(data, name, shape, dtype), image)


@pytest.mark.parametrize("shape", [(48, 64), (48, 64, 3)])
def test_jpeg_keeps_shape_and_dtype_and_stays_close(shape):
    image = np.tile(np.arange(64, dtype=np.uint8) * 4, (48, 1))
    if len(shape) == 3:
        image = np.repeat(image[:, :, None], 3, axis=2)
    data = encoding.encode(image, "jpeg", 95)
    back = encoding.decode(data, "jpeg", shape, "uint8")
    assert back.shape == shape and back.dtype == np.uint8
    assert np.abs(back.astype(int) - image).max() <= 8
    assert len(data) < image.nbytes


@pytest.mark.parametrize(
    "name,quality,says",
    [("webp", 90, "unknown encoding"), ("jpeg", 0, "quality"), ("jpeg", 101, "quality"), ("jpeg", 9.5, "quality")],
)
def test_bad_encoding_or_quality_says_what_is_wrong(name, quality, says):
    with pytest.raises(ProtocolError, match=says):
        encoding.encode(_image((8, 8)), name, quality)


def test_jpeg_refuses_16_bit_frames():
    with pytest.raises(ProtocolError, match="uint8"):
        encoding.encode(_image((8, 8), "uint16"), "jpeg")


def test_garbage_does_not_decode():
    with pytest.raises(ProtocolError, match="could not be decoded"):
        encoding.decode(b"not an image", "jpeg", (8, 8), "uint8")
