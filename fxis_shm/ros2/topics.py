"""One camera's topics as image_transport and camera_info_manager lay them out, under one
base name B (``/NS/NAME``, ``/NS/tuple/NAME``, ``/NS/frames_at/R/NAME``):

    B/image_raw              sensor_msgs/msg/Image, the frame's own pixels
    B/image_raw/compressed   sensor_msgs/msg/CompressedImage (only where asked for, and
                             encoded only while a reader is matched), image_transport's
                             format "ENC; jpeg compressed ENC" (PNG for 16-bit frames)
    B/camera_info            sensor_msgs/msg/CameraInfo with the image's header.stamp

Each frame is serialized once, straight into CDR (fxis_shm.formats.cdr: one copy of the
pixels), and published only if its ring slot still held it after that copy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fxis_shm.client.frames import Frame
from fxis_shm.errors import FxisError
from fxis_shm.formats import cdr, rosnames
from fxis_shm.formats.calibration import Calibration
from fxis_shm.formats.rosmsgs import COMPRESSED, IMAGE, ros_encoding
from fxis_shm.ros2.endpoints import Participant
from fxis_shm.wire import encoding as codec
from fxis_shm.wire.encodecache import EncodeCache

CAMERA_INFO = "sensor_msgs/msg/CameraInfo"


@dataclass(frozen=True)
class Messages:
    """One frame's serialized messages (CDR, padded as DDS wants them)."""

    image: bytes
    camera_info: bytes
    compressed: bytes | None = None


class CameraTopics:
    def __init__(
        self,
        participant: Participant,
        base: str,
        frame_id: str,
        calibration: Calibration | None,
        compressed: bool = False,
    ):
        self.base, self.frame_id, self.calibration = base, frame_id, calibration
        self.image = participant.writer(rosnames.join(base, "image_raw"), IMAGE)
        self.info = participant.writer(rosnames.join(base, "camera_info"), CAMERA_INFO)
        self.compressed = (
            participant.writer(rosnames.join(base, "image_raw", "compressed"), COMPRESSED) if compressed else None
        )
        self._encoded = EncodeCache(size=4)  # this camera's frames: each encoded once
        self.compress_error: str | None = None  # why this camera's frames cannot be compressed

    def publish(self, frame: Frame, stamp_ns: int) -> bool:
        """The frame on every topic, stamped ``stamp_ns`` (ROS time); False, and nothing
        published, if its slot was overwritten while it was being serialized."""
        messages = self.serialize(frame, stamp_ns)
        if not frame.still_valid():
            return False
        self.write(messages)
        return True

    def serialize(self, frame: Frame, stamp_ns: int) -> Messages:
        """The frame's messages, built (its pixels copied into the Image's CDR) but not sent."""
        header = cdr.Header.at(stamp_ns, self.frame_id)
        image = cdr.encode_image_array(header, frame.image, ros_encoding(frame.image), pad=True)
        return Messages(image, self.camera_info(header, frame.image), self._compressed(frame, header))

    def write(self, messages: Messages) -> None:
        self.image.write(messages.image)
        self.info.write(messages.camera_info)
        if messages.compressed is not None and self.compressed is not None:
            self.compressed.write(messages.compressed)

    def camera_info(self, header: cdr.Header, image: np.ndarray) -> bytes:
        c = self.calibration
        if c is None:
            return cdr.encode_camera_info(cdr.CameraInfo(header, image.shape[0], image.shape[1]), pad=True)
        info = cdr.CameraInfo(header, c.height, c.width, c.distortion_model, c.d, c.k, c.r, c.p)
        return cdr.encode_camera_info(info, pad=True)

    def _compressed(self, frame: Frame, header: cdr.Header) -> bytes | None:
        if self.compressed is None or self.compress_error or self.compressed.matched_count() == 0:
            return None
        encoding = ros_encoding(frame.image)
        kind = codec.JPEG if frame.image.dtype == np.uint8 else codec.PNG  # JPEG has no 16 bits
        target = encoding if kind == codec.PNG else "mono8" if encoding == "mono8" else "bgr8"
        try:
            data = self._encoded.get((frame.camera, frame.generation, frame.frame_id), lambda: frame.image, kind, None)
        except FxisError as exc:  # e.g. float pixels: the raw topic still carries them
            self.compress_error = f"{frame.camera}: no {kind} for {encoding} frames ({exc})"
            return None
        return cdr.encode_compressed_image(header, f"{encoding}; {kind} compressed {target}", data, pad=True)
