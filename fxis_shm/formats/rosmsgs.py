"""The ROS 2 messages a recording holds (docs/recording.md): their definitions, as a
rosbag2 MCAP file stores them (the ``ros2msg`` schema text, dependencies appended), the
topic names, and the message contents made from a frame.

Pure: frames and numbers in, message dicts out (``mcap_ros2`` serialises them to CDR).
"""

from __future__ import annotations

import numpy as np

from fxis_shm.errors import InvalidArgument
from fxis_shm.wire import encoding as codec

IMAGE, COMPRESSED, TUPLE = "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage", "fxis_msgs/msg/FrameTuple"
TUPLES_TOPIC = "/fxis/tuples"
# Video (fxis record --codec): Foxglove's CompressedVideo, as its ROS 2 package foxglove_msgs
# defines it, one frame per message; and beside it, message for message, the frame each is.
VIDEO, VIDEO_FRAME = "foxglove_msgs/msg/CompressedVideo", "fxis_msgs/msg/VideoFrame"
# A robot's joints (fxis export --lerobot samples them as observation.state and action).
JOINT_STATE = "sensor_msgs/msg/JointState"

_SEP = "=" * 80 + "\n"
_HEADER_DEPS = (
    _SEP + "MSG: std_msgs/Header\n"
    "builtin_interfaces/Time stamp\n"
    "string frame_id\n" + _SEP + "MSG: builtin_interfaces/Time\n"
    "int32 sec\n"
    "uint32 nanosec\n"
)

DEFINITIONS = {
    IMAGE: (
        "std_msgs/Header header\n"
        "uint32 height\n"
        "uint32 width\n"
        "string encoding\n"
        "uint8 is_bigendian\n"
        "uint32 step\n"
        "uint8[] data\n" + _HEADER_DEPS
    ),
    COMPRESSED: ("std_msgs/Header header\nstring format\nuint8[] data\n" + _HEADER_DEPS),
    # One synchronized tuple: header.stamp is the step time, which every image of the tuple
    # carries too; each camera's frame id, generation and capture time, in the same order.
    TUPLE: (
        "std_msgs/Header header\n"
        "string[] cameras\n"
        "uint64[] frame_ids\n"
        "uint32[] generations\n"
        "builtin_interfaces/Time[] capture_stamps\n" + _HEADER_DEPS
    ),
    # foxglove_msgs/msg/CompressedVideo (github.com/foxglove/schemas, ros_foxglove_msgs): the
    # fields of the foxglove.CompressedVideo schema; format "h264", "h265", "vp9" or "av1".
    VIDEO: (
        "builtin_interfaces/Time timestamp\n"
        "string frame_id\n"
        "uint8[] data\n"
        "string format\n" + _SEP + "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
    ),
    # What lossy video cannot be trusted to keep: the frame id and generation of the message of
    # the same stamp (and index) on the video topic, and whether it is a keyframe.
    VIDEO_FRAME: ("std_msgs/Header header\nuint64 frame_id\nuint32 generation\nbool keyframe\n" + _HEADER_DEPS),
    JOINT_STATE: (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n"
        + _HEADER_DEPS
    ),
}

# ROS encoding names (sensor_msgs/image_encodings.hpp) of the layouts the rings hold.
_ENCODINGS = {
    (1, "uint8"): "mono8",
    (3, "uint8"): "bgr8",
    (4, "uint8"): "bgra8",
    (1, "uint16"): "mono16",
    (1, "float32"): "32FC1",
}
_LAYOUTS = {name: layout for layout, name in _ENCODINGS.items()}


def image_topic(camera: str, compressed: bool = False) -> str:
    return f"/{camera}/image_raw" + ("/compressed" if compressed else "")


def video_topic(camera: str) -> str:
    return f"/{camera}/video"


def video_frames_topic(camera: str) -> str:
    return f"/{camera}/video/frames"


def video_messages(packet, camera: str, codec_name: str) -> tuple[dict, dict]:
    """The CompressedVideo message of one encoded frame (fxis_shm.formats.videoencoder's
    ``Packet``) and its VideoFrame beside it, both stamped with the frame's capture time."""
    video = {"timestamp": stamp(packet.t_ns), "frame_id": camera, "data": packet.data, "format": codec_name}
    info = {
        "header": header(packet.t_ns, camera),
        "frame_id": packet.frame_id,
        "generation": packet.generation,
        "keyframe": packet.keyframe,
    }
    return video, info


def stamp(ns: int) -> dict:
    """A builtin_interfaces/Time (whole seconds and nanoseconds) of ``ns``."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def stamp_ns(time) -> int:
    """ns of a decoded builtin_interfaces/Time (any object with sec and nanosec)."""
    return time.sec * 1_000_000_000 + time.nanosec


def header(t_ns: int, frame_id: str) -> dict:
    return {"stamp": stamp(t_ns), "frame_id": frame_id}


def ros_encoding(image: np.ndarray) -> str:
    channels = 1 if image.ndim == 2 else image.shape[2]
    try:
        return _ENCODINGS[(channels, image.dtype.name)]
    except KeyError:
        raise InvalidArgument(f"no ROS image encoding for {channels}-channel {image.dtype.name} frames") from None


def image_message(image: np.ndarray, t_ns: int, camera: str) -> dict:
    """A sensor_msgs/msg/Image of a frame: step is the bytes of one row."""
    image = np.ascontiguousarray(image)
    return {
        "header": header(t_ns, camera),
        "height": image.shape[0],
        "width": image.shape[1],
        "encoding": ros_encoding(image),
        "is_bigendian": 0,
        "step": image.strides[0],
        "data": image.tobytes(),
    }


def compressed_message(jpeg: bytes, t_ns: int, camera: str) -> dict:
    """A sensor_msgs/msg/CompressedImage. ``format`` is the plain "jpeg": Foxglove takes
    only the plain names, and ROS's compressed_image_transport reads it too (the verbose
    "bgr8; jpeg compressed bgr8" it writes is what Foxglove does not show)."""
    return {"header": header(t_ns, camera), "format": "jpeg", "data": jpeg}


def frame_message(frame, t_ns: int, encoding: str, quality: int | None = None) -> tuple[str, str, dict, int]:
    """(topic, type, message, payload bytes) of a frame as a recording holds it: raw as an
    Image, or JPEG-encoded as a CompressedImage on the ``compressed`` topic."""
    if encoding == codec.JPEG:
        data = codec.encode(frame.image, codec.JPEG, codec.DEFAULT_JPEG_QUALITY if quality is None else quality)
        return image_topic(frame.camera, True), COMPRESSED, compressed_message(data, t_ns, frame.camera), len(data)
    message = image_message(frame.image, t_ns, frame.camera)
    return image_topic(frame.camera), IMAGE, message, frame.image.nbytes


def tuple_message(t_step: int, frames: list) -> dict:
    """The /fxis/tuples message of one tuple of ``fxis_shm.Frame``s."""
    return {
        "header": header(t_step, "fxis"),
        "cameras": [f.camera for f in frames],
        "frame_ids": [f.frame_id for f in frames],
        "generations": [f.generation for f in frames],
        "capture_stamps": [stamp(f.service_t_capture) for f in frames],
    }


def image_array(msg) -> np.ndarray:
    """The pixels of a decoded sensor_msgs/msg/Image, shaped (h, w) or (h, w, c)."""
    try:
        channels, dtype = _LAYOUTS[msg.encoding]
    except KeyError:
        raise InvalidArgument(f"image encoding {msg.encoding!r} is not one of {', '.join(_LAYOUTS)}") from None
    row = msg.width * channels * np.dtype(dtype).itemsize
    data = np.frombuffer(bytes(msg.data) if not isinstance(msg.data, (bytes, bytearray)) else msg.data, np.uint8)
    rows = data[: msg.height * msg.step].reshape(msg.height, msg.step)[:, :row]
    image = np.ascontiguousarray(rows).view(dtype)
    return image.reshape(msg.height, msg.width) if channels == 1 else image.reshape(msg.height, msg.width, channels)
