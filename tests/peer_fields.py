"""What the two test peers share, our own Cyclone peer (tests/dds_peer) and the real rclpy node
(tests/rclpy_peer.py): their command line, their run until told to stop, and what they report of
a message they received as JSON fields (their messages have the same attribute names). Standard
library only: the ROS venvs hold nothing of ours.
"""

import argparse
import base64
import hashlib
import signal
from typing import Any


def peer_parser(prog: str, description: str) -> argparse.ArgumentParser:
    """The options every peer takes (docs: tests/dds_peer/__main__.py)."""
    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument("--domain", type=int, required=True)
    parser.add_argument("--sub", action="append", default=[], metavar="TOPIC:TYPE:PROFILE")
    parser.add_argument("--pub-header", action="append", default=[], metavar="TOPIC[:PROFILE]")
    parser.add_argument("--data", action="store_true", help="samples carry their data, base64")
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds before the peer ends anyway")
    return parser


def run_peer(node: Any, lifetime: float) -> int:
    """Run ``node`` (its ``run(lifetime)``) until stdin closes, SIGTERM or ``lifetime`` s."""

    def stop(*_: object) -> None:
        node.stopping = True

    signal.signal(signal.SIGTERM, stop)
    node.run(lifetime)
    return 0


HEADER = "std_msgs/msg/Header"


def describe(ros_type: str, message: Any, with_data: bool) -> dict[str, Any]:
    """A message's fields as tests/dds_peer reports them."""
    if ros_type == HEADER:
        return {"stamp": [message.stamp.sec, message.stamp.nanosec], "frame_id": message.frame_id}
    if ros_type == "std_msgs/msg/String":
        return {"data": message.data}
    fields: dict[str, Any] = {"stamp": [message.header.stamp.sec, message.header.stamp.nanosec]}
    fields["frame_id"] = message.header.frame_id
    if ros_type == "diagnostic_msgs/msg/DiagnosticArray":
        fields["status"] = [
            {
                "level": int.from_bytes(bytes(s.level), "little") if isinstance(s.level, bytes) else int(s.level),
                "name": s.name,
                "message": s.message,
                "hardware_id": s.hardware_id,
                "values": {kv.key: kv.value for kv in s.values},
            }
            for s in message.status
        ]
        return fields
    if ros_type == "sensor_msgs/msg/CameraInfo":
        roi = message.roi
        fields.update(height=message.height, width=message.width, distortion_model=message.distortion_model)
        fields.update(d=list(message.d), k=list(message.k), r=list(message.r), p=list(message.p))
        fields.update(binning=[message.binning_x, message.binning_y])
        fields.update(roi=[roi.x_offset, roi.y_offset, roi.height, roi.width, bool(roi.do_rectify)])
        return fields
    data = bytes(message.data)
    fields.update(size=len(data), sha256=hashlib.sha256(data).hexdigest(), head=data[:16].hex(), tail=data[-16:].hex())
    if with_data:
        fields["data"] = base64.b64encode(data).decode()
    if ros_type == "sensor_msgs/msg/CompressedImage":
        fields["format"] = message.format
        return fields
    fields.update(height=message.height, width=message.width, encoding=message.encoding, step=message.step)
    fields["is_bigendian"] = message.is_bigendian
    last, width = max(message.height - 1, 0) * message.step, min(16, message.step)
    fields["rows"] = [data[:width].hex(), data[last : last + width].hex()]  # where the pixel stamp is
    return fields
