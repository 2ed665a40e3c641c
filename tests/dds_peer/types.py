"""The test peer's own ROS message types, written from the .msg files (builtin_interfaces,
std_msgs, sensor_msgs) and serialized by cyclonedds itself: nothing shared with
``fxis_shm.formats.cdr`` or ``fxis_shm.ros2.dds``, so that a layout mistake there shows here.
"""

# No ``from __future__ import annotations``: cyclonedds cannot resolve string annotations.

from dataclasses import dataclass

from cyclonedds.idl import IdlStruct, annotations as annotate, types


@dataclass
@annotate.final
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: types.int32
    nanosec: types.uint32


@dataclass
@annotate.final
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
@annotate.final
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


@dataclass
@annotate.final
class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
    header: Header
    height: types.uint32
    width: types.uint32
    encoding: str
    is_bigendian: types.uint8
    step: types.uint32
    data: types.sequence[types.uint8]


@dataclass
@annotate.final
class CompressedImage(IdlStruct, typename="sensor_msgs::msg::dds_::CompressedImage_"):
    header: Header
    format: str
    data: types.sequence[types.uint8]


@dataclass
@annotate.final
class RegionOfInterest(IdlStruct, typename="sensor_msgs::msg::dds_::RegionOfInterest_"):
    x_offset: types.uint32
    y_offset: types.uint32
    height: types.uint32
    width: types.uint32
    do_rectify: bool


@dataclass
@annotate.final
class CameraInfo(IdlStruct, typename="sensor_msgs::msg::dds_::CameraInfo_"):
    header: Header
    height: types.uint32
    width: types.uint32
    distortion_model: str
    d: types.sequence[types.float64]
    k: types.array[types.float64, 9]
    r: types.array[types.float64, 9]
    p: types.array[types.float64, 12]
    binning_x: types.uint32
    binning_y: types.uint32
    roi: RegionOfInterest


BY_ROS_NAME: dict[str, type[IdlStruct]] = {
    "std_msgs/msg/Header": Header,
    "std_msgs/msg/String": String,
    "sensor_msgs/msg/Image": Image,
    "sensor_msgs/msg/CompressedImage": CompressedImage,
    "sensor_msgs/msg/CameraInfo": CameraInfo,
}
