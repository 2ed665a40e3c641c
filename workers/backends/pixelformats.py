"""GenICam pixel formats (PFNC names) as the images the rings store: the one
table both GenICam backends (Aravis, GenTL) read, and the conversion of a
delivered buffer into an image.

OpenCV names its Bayer codes after the second row's pattern, one row and column
down from GenICam's: BayerRG (an RGGB mosaic) is OpenCV's BayerBG.
tests/backends/test_aravis.py and test_genicam.py check this on a known mosaic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fxis_shm.shm.ring import FrameLayout


@dataclass(frozen=True)
class PixelFormat:
    """How a GenICam pixel format becomes an image in the ring."""

    dtype: str
    channels: int  # in the camera's buffer
    to_bgr: str | None = None  # cv2 colour conversion to BGR (unless raw=true)


_BAYER_CV2 = {
    "RG": "COLOR_BayerBG2BGR",
    "BG": "COLOR_BayerRG2BGR",
    "GR": "COLOR_BayerGB2BGR",
    "GB": "COLOR_BayerGR2BGR",
}
PIXEL_FORMATS: dict[str, PixelFormat] = {
    "Mono8": PixelFormat("uint8", 1),
    **{f"Mono{bits}": PixelFormat("uint16", 1) for bits in (10, 12, 14, 16)},  # unpacked, in 16 bits
    "RGB8": PixelFormat("uint8", 3, "COLOR_RGB2BGR"),
    "BGR8": PixelFormat("uint8", 3),
    "RGBa8": PixelFormat("uint8", 4, "COLOR_RGBA2BGR"),
    "BGRa8": PixelFormat("uint8", 4, "COLOR_BGRA2BGR"),
    **{f"Bayer{p}8": PixelFormat("uint8", 1, code) for p, code in _BAYER_CV2.items()},
    **{f"Bayer{p}{bits}": PixelFormat("uint16", 1, code) for p, code in _BAYER_CV2.items() for bits in (10, 12, 16)},
}


def image_layout(pixel_format: str, width: int, height: int, raw: bool) -> FrameLayout:
    fmt = PIXEL_FORMATS[pixel_format]
    channels = 3 if fmt.to_bgr is not None and not raw else fmt.channels
    return FrameLayout(height, width, channels, fmt.dtype)


def to_image(data: np.ndarray, pixel_format: str, width: int, height: int, raw: bool) -> np.ndarray:
    """A buffer's pixel values (1-D, rows maybe padded) as a new (h, w[, c]) array
    that owns its memory."""
    import cv2

    fmt = PIXEL_FORMATS[pixel_format]
    channels = fmt.channels
    flat = data.view(fmt.dtype) if data.dtype != np.dtype(fmt.dtype) else data
    per_row = flat.size // height if height else 0
    if per_row < width * channels:
        raise ValueError(f"a {pixel_format} buffer of {data.size} values is too small for {width}x{height}")
    rows = flat[: per_row * height].reshape(height, per_row)[:, : width * channels]
    image = rows.reshape(height, width, channels) if channels > 1 else rows
    if fmt.to_bgr is None or raw:
        return np.array(image)  # a copy: the buffer goes back to the producer
    return cv2.cvtColor(np.ascontiguousarray(image), getattr(cv2, fmt.to_bgr))
