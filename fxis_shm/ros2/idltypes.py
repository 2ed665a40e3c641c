"""The ROS message types the bridge writes and reads, declared as Cyclone DDS ``IdlStruct``s, and
their RIHS01 type hashes: what Cyclone needs to match a ROS 2 endpoint (fxis_shm.ros2.dds uses
them; the bytes themselves are written by fxis_shm.formats.cdr).
"""

# No ``from __future__ import annotations`` here: cyclonedds resolves an IdlStruct's string
# annotations ("t.uint32") by importing a module of that name, and fails.

from dataclasses import dataclass

from cyclonedds.idl import IdlStruct, types as t
from cyclonedds.idl.annotations import final

from fxis_shm.formats.rosnames import dds_type_name

# RIHS01 type hashes (REP-2011), the same in Iron, Jazzy and Kilted for these types; Humble has
# none and ignores USER_DATA. tests/unit/test_cdr.py checks them against rosbags' hash_rihs01.
TYPE_HASHES: dict[str, str] = {
    "std_msgs/msg/Header": "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
    "std_msgs/msg/String": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "sensor_msgs/msg/Image": "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
    "sensor_msgs/msg/CompressedImage": "RIHS01_15640771531571185e2efc8a100baf923961a4d15d5569652e6cb6691e8e371a",
    "sensor_msgs/msg/CameraInfo": "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275",
    "diagnostic_msgs/msg/DiagnosticArray": "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
    "rmw_dds_common/msg/ParticipantEntitiesInfo": (
        "RIHS01_e725f4a506958c79f95dd693b965722c57b19cd18e7eff984f49561b93dc985d"
    ),
}


# The ROS types as IdlStructs, written from the .msg files. Never used to serialize (cdr does);
# they give Cyclone the topic's type name, key-less-ness and extensibility, the TypeInformation
# it advertises and the CDR ops it checks written buffers against, so they must match the ROS
# IDL exactly: ``data`` is sequence<uint8>, not bytes.


@dataclass
@final
class _Time(IdlStruct, typename="builtin_interfaces.msg.dds_.Time_"):
    sec: t.int32
    nanosec: t.uint32


@dataclass
@final
class _Header(IdlStruct, typename="std_msgs.msg.dds_.Header_"):
    stamp: _Time
    frame_id: str


@dataclass
@final
class _String(IdlStruct, typename="std_msgs.msg.dds_.String_"):
    data: str


@dataclass
@final
class _Image(IdlStruct, typename="sensor_msgs.msg.dds_.Image_"):
    header: _Header
    height: t.uint32
    width: t.uint32
    encoding: str
    is_bigendian: t.uint8
    step: t.uint32
    data: t.sequence[t.uint8]


@dataclass
@final
class _CompressedImage(IdlStruct, typename="sensor_msgs.msg.dds_.CompressedImage_"):
    header: _Header
    format: str
    data: t.sequence[t.uint8]


@dataclass
@final
class _RegionOfInterest(IdlStruct, typename="sensor_msgs.msg.dds_.RegionOfInterest_"):
    x_offset: t.uint32
    y_offset: t.uint32
    height: t.uint32
    width: t.uint32
    do_rectify: bool


@dataclass
@final
class _CameraInfo(IdlStruct, typename="sensor_msgs.msg.dds_.CameraInfo_"):
    header: _Header
    height: t.uint32
    width: t.uint32
    distortion_model: str
    d: t.sequence[t.float64]
    k: t.array[t.float64, 9]
    r: t.array[t.float64, 9]
    p: t.array[t.float64, 12]
    binning_x: t.uint32
    binning_y: t.uint32
    roi: _RegionOfInterest


@dataclass
@final
class _KeyValue(IdlStruct, typename="diagnostic_msgs.msg.dds_.KeyValue_"):
    key: str
    value: str


@dataclass
@final
class _DiagnosticStatus(IdlStruct, typename="diagnostic_msgs.msg.dds_.DiagnosticStatus_"):
    level: t.byte
    name: str
    message: str
    hardware_id: str
    values: t.sequence[_KeyValue]


@dataclass
@final
class _DiagnosticArray(IdlStruct, typename="diagnostic_msgs.msg.dds_.DiagnosticArray_"):
    header: _Header
    status: t.sequence[_DiagnosticStatus]


@dataclass
@final
class _Gid(IdlStruct, typename="rmw_dds_common.msg.dds_.Gid_"):
    data: t.array[t.uint8, 16]


@dataclass
@final
class _NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common.msg.dds_.NodeEntitiesInfo_"):
    node_namespace: t.bounded_str[256]
    node_name: t.bounded_str[256]
    reader_gid_seq: t.sequence[_Gid]
    writer_gid_seq: t.sequence[_Gid]


@dataclass
@final
class _ParticipantEntitiesInfo(IdlStruct, typename="rmw_dds_common.msg.dds_.ParticipantEntitiesInfo_"):
    gid: _Gid
    node_entities_info_seq: t.sequence[_NodeEntitiesInfo]


IDL_TYPES: dict[str, type[IdlStruct]] = {
    "std_msgs/msg/Header": _Header,
    "std_msgs/msg/String": _String,
    "sensor_msgs/msg/Image": _Image,
    "sensor_msgs/msg/CompressedImage": _CompressedImage,
    "sensor_msgs/msg/CameraInfo": _CameraInfo,
    "diagnostic_msgs/msg/DiagnosticArray": _DiagnosticArray,
    "rmw_dds_common/msg/ParticipantEntitiesInfo": _ParticipantEntitiesInfo,
}


def check_ros_compatible(idl: type[IdlStruct], ros_type: str) -> None:
    """Refuse a declaration a ROS reader would not match: another name, not final or not XCDR1
    (an @appendable or @mutable type, or optional members, default to XCDR2), or keyed."""
    spec = idl.__idl__
    spec.populate()
    if spec.idl_transformed_typename != dds_type_name(ros_type):
        raise TypeError(f"{idl} is named {spec.idl_transformed_typename}, ROS wants {dds_type_name(ros_type)}")
    extensibility = idl.__idl_annotations__.get("extensibility", "final")  # cyclonedds' default: final
    if extensibility != "final" or spec.default_version != 1 or not spec.supported_versions & 1:
        raise TypeError(f"{idl} is not final/XCDR1 (ROS readers only accept XCDR1): {extensibility}")
    if not spec.keyless:
        raise TypeError(f"{idl} has key fields; ROS topics are key-less")
