"""A video track's frames decoded back into images, message by message (the ``bag`` camera's
replay of ``/NAME/video``): FFmpeg's decoders through PyAV.

Each CompressedVideo message is one frame (no B-frames), so each decodes into one picture at
once, in order, from the track's keyframe before it. The video carries 8-bit 4:2:0 pictures,
not whether the camera was mono or colour: ``pixels_of`` tells them apart by the chroma of
the first picture (a mono8 camera's frames are encoded with neutral chroma, 128 everywhere).
"""

from __future__ import annotations

import numpy as np

from fxis_shm.errors import InvalidArgument
from fxis_shm.formats.videoencoder import require_av

DECODERS = {"h264": "h264", "h265": "hevc", "av1": "libdav1d"}  # the format field -> FFmpeg's decoder
MONO, COLOUR = "gray", "bgr24"  # PyAV's names of the mono8 and bgr8 layouts
_NEUTRAL, _CHROMA_SLACK = 128, 2  # a mono picture's chroma, give or take the codec's rounding


class TrackDecoder:
    """``decode(data)``: the picture of one message, as ``pixels`` (MONO or COLOUR)."""

    def __init__(self, codec: str, pixels: str = COLOUR):
        if codec not in DECODERS:
            raise InvalidArgument(f"video format {codec!r}: the bag camera decodes {', '.join(DECODERS)}")
        av = require_av()
        self._av, self.codec, self.pixels = av, codec, pixels
        self._context = av.CodecContext.create(DECODERS[codec], "r")
        if codec == "av1":
            self._context.options = {"max_frame_delay": "1"}  # dav1d's threads otherwise hold frames back

    def picture(self, data: bytes):
        """The decoded picture (a PyAV VideoFrame) of one message; InvalidArgument if none."""
        try:
            pictures = self._context.decode(self._av.Packet(data))
        except self._av.FFmpegError as exc:
            raise InvalidArgument(f"a {self.codec} frame of {len(data)} bytes did not decode: {exc}") from None
        if len(pictures) != 1:
            raise InvalidArgument(
                f"a {self.codec} message decoded into {len(pictures)} pictures, not one "
                "(no keyframe before it, or a stream with B-frames)"
            )
        return pictures[0]

    def decode(self, data: bytes) -> np.ndarray:
        return self.picture(data).to_ndarray(format=self.pixels)


def pixels_of(picture) -> str:
    """MONO if the picture's chroma is neutral (its camera was mono8), else COLOUR."""
    planes = picture.reformat(format="yuv420p").to_ndarray()  # Y rows, then U and V packed below
    chroma = planes[picture.height :].astype(np.int16)
    return MONO if np.abs(chroma - _NEUTRAL).max() <= _CHROMA_SLACK else COLOUR
