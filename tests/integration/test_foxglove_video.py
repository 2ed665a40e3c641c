"""Our video track against Foxglove's own code. The same encoded frames are written twice: by
the recorder's path (fxis_shm.formats.videotracks.write_packets into a rosbag2 bag: ROS 2
foxglove_msgs/msg/CompressedVideo in CDR) and by the foxglove SDK's MCAP writer with its own
message class (foxglove.messages.CompressedVideo: protobuf). Each file is read back by a
reader of its own kind (rosbags for ours; protobuf, by the schema the SDK's file carries, for
theirs) and the two are compared field by field (docs/recording.md, "Checked against
Foxglove's SDK")."""

from __future__ import annotations

import foxglove
import numpy as np
import pytest
from foxglove.channels import CompressedVideoChannel
from foxglove.messages import CompressedVideo, Timestamp
from mcap.reader import make_reader

from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagfile import BagWriter, mcap_file
from fxis_shm.formats.stamp import write_stamp
from fxis_shm.formats.videochoice import Choice
from fxis_shm.formats.videoencoder import StreamEncoder
from fxis_shm.formats.videotracks import write_packets

from ..foxglove_decode import message_class
from .bags import read_bag

pytestmark = pytest.mark.integration
CAMERA, CODEC = "left", "h264"
TO_REALTIME = 1_764_000_000_000_000_000  # what the recorder adds to a capture time for the log time


@pytest.fixture(scope="module")
def packets():
    """Eight 160x120 mono8 frames stamped with ids 100..107, 50 ms apart but for one dropped
    frame (a 100 ms gap), in h264 with a keyframe every 0.2 s."""
    encoder = StreamEncoder(CAMERA, Choice(CODEC, "libx264", False), 23, "veryfast", 0.2, 20.0)
    encoded = []
    for i in range(8):
        image = np.full((120, 160), 40 + 20 * i, np.uint8)
        write_stamp(image, 100 + i)
        encoded += encoder.encode(image, 3_000_000_123 + 50_000_000 * (i + (i >= 5)), 100 + i, 0)
    encoded += encoder.finish()
    assert [p.frame_id for p in encoded] == list(range(100, 108))
    return encoded


@pytest.fixture(scope="module")
def ours(packets, tmp_path_factory):
    folder = tmp_path_factory.mktemp("ours") / "bag"
    bag = BagWriter(str(folder))
    write_packets(bag, CAMERA, CODEC, packets, TO_REALTIME)
    bag.close()
    return folder


@pytest.fixture(scope="module")
def theirs(packets, tmp_path_factory):
    """The SDK's MCAP of the same packets: its channel, its message class, its writer."""
    path = tmp_path_factory.mktemp("sdk") / "sdk.mcap"
    context = foxglove.Context()  # of this test alone: nothing else logs into the file
    writer = foxglove.open_mcap(str(path), context=context)
    channel = CompressedVideoChannel(rosmsgs.video_topic(CAMERA), context=context)
    for p in packets:
        sec, nsec = divmod(p.t_ns, 1_000_000_000)
        message = CompressedVideo(timestamp=Timestamp(sec, nsec), frame_id=CAMERA, data=p.data, format=CODEC)
        channel.log(message, log_time=p.t_ns + TO_REALTIME)
    writer.close()
    return path


def declared(path, topic: str):
    """(schema, channel, [(log_time, raw message bytes)]) of ``topic`` in an MCAP file."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        found = [(s, c, m) for s, c, m in reader.iter_messages(topics=[topic])]
    schema, channel, _ = found[0]
    return schema, channel, [(m.log_time, m.data) for _, _, m in found]


def test_every_frame_carries_what_the_sdks_message_carries(packets, ours, theirs):
    topic = rosmsgs.video_topic(CAMERA)
    mine = read_bag(ours).messages[topic]  # rosbags' CDR reading
    schema, _, raw = declared(theirs, topic)
    sdk_class = message_class(schema.name, schema.data)  # protobuf, by the schema in the SDK's file
    sdk = [(log_time, sdk_class.FromString(data)) for log_time, data in raw]
    assert len(mine) == len(sdk) == len(packets)
    for m, (log_time, s), packet, (_, sdk_bytes) in zip(mine, sdk, packets, raw):
        assert m.log_time == log_time == packet.t_ns + TO_REALTIME
        assert (m.msg.timestamp.sec, m.msg.timestamp.nanosec) == (s.timestamp.seconds, s.timestamp.nanos)
        assert m.msg.frame_id == s.frame_id == CAMERA
        assert bytes(m.msg.data) == s.data == packet.data  # the bitstream, byte for byte
        assert m.msg.format == s.format == CODEC
        # ours, made into the SDK's message, is the SDK's message byte for byte
        again = CompressedVideo(
            timestamp=Timestamp(m.msg.timestamp.sec, m.msg.timestamp.nanosec),
            frame_id=m.msg.frame_id,
            data=bytes(m.msg.data),
            format=m.msg.format,
        )
        assert again.encode() == sdk_bytes
    # the stamps keep the capture times to the nanosecond, the dropped frame's gap too
    stamps = [rosmsgs.stamp_ns(m.msg.timestamp) for m in mine]
    assert stamps == [p.t_ns for p in packets] and stamps[5] - stamps[4] == 100_000_000
    # and the frame id, which the SDK's message has no field for, beside it on /NAME/video/frames
    frames = read_bag(ours).messages[rosmsgs.video_frames_topic(CAMERA)]
    assert [(f.msg.frame_id, rosmsgs.stamp_ns(f.msg.header.stamp)) for f in frames] == [
        (p.frame_id, p.t_ns) for p in packets
    ]


def ros_fields(definition: str) -> list[tuple[str, str]]:
    """(type, name) of a ROS message definition's own fields (before its dependencies)."""
    own = definition.split("=" * 80)[0]
    return [tuple(line.split()[:2]) for line in own.splitlines() if line.strip()]


def test_the_channels_declare_the_same_fields_in_their_own_type_systems(ours, theirs):
    topic = rosmsgs.video_topic(CAMERA)
    schema, channel, _ = declared(mcap_file(str(ours)), topic)
    assert (schema.name, schema.encoding, channel.message_encoding) == (rosmsgs.VIDEO, "ros2msg", "cdr")
    sdk_schema, sdk_channel, _ = declared(theirs, topic)
    assert (sdk_schema.name, sdk_schema.encoding, sdk_channel.message_encoding) == (
        "foxglove.CompressedVideo",
        "protobuf",
        "protobuf",
    )
    assert sdk_channel.topic == channel.topic
    descriptor = message_class(sdk_schema.name, sdk_schema.data).DESCRIPTOR
    sdk_fields = [(f.name, f.message_type.full_name if f.message_type else f.type) for f in descriptor.fields]
    assert [name for name, _ in sdk_fields] == [name for _, name in ros_fields(schema.data.decode())]
    # the same names in the same order; the types each system's own (docs/recording.md)
    assert ros_fields(schema.data.decode()) == [
        ("builtin_interfaces/Time", "timestamp"),
        ("string", "frame_id"),
        ("uint8[]", "data"),
        ("string", "format"),
    ]
    proto = descriptor.fields[0]  # (its type constants)
    assert sdk_fields == [
        ("timestamp", "google.protobuf.Timestamp"),
        ("frame_id", proto.TYPE_STRING),
        ("data", proto.TYPE_BYTES),
        ("format", proto.TYPE_STRING),
    ]
