"""What a test peer reports of a message it received, as JSON fields: shared by our own Cyclone
peer (tests/dds_peer) and the real rclpy node (tests/rclpy_peer.py), whose messages have the same
attribute names. Standard library only: the ROS venvs hold nothing of ours.
"""

import base64
import hashlib
from typing import Any

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
