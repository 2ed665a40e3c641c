"""What fxis_shm.ros2.dds puts on the wire, judged by an independent ROS 2-like peer process
(tests/dds_peer: its own types, cyclonedds' own serializer): byte-for-byte messages and stamps
for SensorData and default subscribers, the USER_DATA ROS writes, Header requests the other
way, and the mismatches ROS would refuse, seen refused from both sides.

Each test has a DDS domain of its own, keeps every packet on 127.0.0.1, waits on conditions
with deadlines and ends its peer in ``with``.
"""

import base64
import hashlib
import time

import numpy as np
import pytest
from cyclonedds.core import DDSException
from cyclonedds.idl import IdlStruct, types as t
from cyclonedds.idl.annotations import appendable

from fxis_shm.formats import cdr
from fxis_shm.formats.rosnames import dds_type_name
from fxis_shm.formats.stamp import read_stamp, write_stamp
from fxis_shm.ros2 import dds, idltypes

from ..conftest import wait_until
from ..dds_peer import DEADLINE, Peer, domain_id, loopback_config, stamp_rows

pytestmark = pytest.mark.integration

IMAGE, INFO, COMPRESSED = "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo", "sensor_msgs/msg/CompressedImage"
IMAGE_TOPIC, INFO_TOPIC, COMPRESSED_TOPIC = "/cam0/image_raw", "/cam0/camera_info", "/cam0/image_raw/compressed"


@pytest.fixture
def domain() -> int:
    return domain_id()


@pytest.fixture
def node(domain):
    with dds.RosParticipant(domain, loopback_config()) as participant:
        yield participant


def step_of(array: np.ndarray) -> int:
    return array.shape[1] * array.itemsize * (array.shape[2] if array.ndim == 3 else 1)


# ------------------------------------------------------------------------------------ no peer


def test_the_idl_declarations_are_what_ros_matches():
    for ros_type, idl in idltypes.IDL_TYPES.items():
        idltypes.check_ros_compatible(idl, ros_type)
        assert idl.__idl__.default_version == 1  # XCDR1
        # The TypeInformation Cyclone advertises: every struct final, none keyed, ROS's names.
        mapping = repr(idl.__idl__.get_type_mapping())
        assert "IS_FINAL=True" in mapping and "IS_APPENDABLE=True" not in mapping and "IS_MUTABLE=True" not in mapping
        assert "IS_KEY=True" not in mapping
        assert f"type_name='{dds_type_name(ros_type)}'" in mapping

    @appendable
    class Image_(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
        data: t.sequence[t.uint8]

    with pytest.raises(TypeError, match="final/XCDR1"):
        idltypes.check_ros_compatible(Image_, IMAGE)
    with pytest.raises(TypeError, match="named"):
        idltypes.check_ros_compatible(idltypes.IDL_TYPES[IMAGE], COMPRESSED)


def test_the_loopback_config_selects_only_lo(domain, tmp_path):
    trace = tmp_path / "cyclonedds.log"
    with dds.RosParticipant(domain, loopback_config(trace_file=str(trace))):
        pass
    lines = trace.read_text().splitlines()
    selected = [line for line in lines if "selected interfaces:" in line]
    assert selected and all("selected interfaces: lo " in line for line in selected), selected
    assert any("AllowMulticast/#text: false" in line for line in lines)


def test_cyclone_refuses_malformed_cdr(node):
    writer = node.writer("/lab/bad", "std_msgs/msg/Header")
    writer.write(cdr.encode_header(cdr.Header(1, 2, "ok")))
    too_long = cdr.CDR_LE_HEADER + bytes.fromhex("01000000 02000000 ff000000")  # a 255-byte string, absent
    no_nul = cdr.encode_header(cdr.Header(1, 2, "abc"))[:-1] + b"x"
    for payload in (too_long, no_nul):
        with pytest.raises(DDSException):
            writer.write(payload)


def test_a_writer_without_readers_waits_for_them_until_its_deadline(node):
    writer = node.writer("/lab/nobody", IMAGE)
    assert writer.matched_count() == 0
    assert writer.wait_for_readers(1, timeout=0.2) is False


def test_a_frame_is_encoded_and_written_in_well_under_a_millisecond_a_megabyte(node):
    """No reader, so no network in the figure: what the bridge pays per frame. The binding's
    own serializer took 34 ms for this frame; one memcpy and Cyclone's check take about 60 us."""
    writer = node.writer("/lab/timing", IMAGE)
    frame = np.random.default_rng(3).integers(0, 256, (1024, 1360), np.uint8)
    best = float("inf")
    for _ in range(10):
        start = time.perf_counter()
        writer.write(cdr.encode_image_array(cdr.Header(1, 2, "cam0"), frame, "mono8", pad=True))
        best = min(best, time.perf_counter() - start)
    assert best < 0.005, f"encode + write took {best * 1e6:.0f} us"


# ------------------------------------------------------------------------------------ with the peer


def test_images_camera_info_and_compressed_images_reach_a_ros_like_peer_byte_for_byte(node, domain):
    subscribe = [
        (IMAGE_TOPIC, IMAGE, "sensor_data"),
        (IMAGE_TOPIC, IMAGE, "default"),
        (INFO_TOPIC, INFO, "default"),
        (COMPRESSED_TOPIC, COMPRESSED, "sensor_data"),
    ]
    with Peer(domain, subscribe) as peer:
        images, info = node.writer(IMAGE_TOPIC, IMAGE), node.writer(INFO_TOPIC, INFO)
        compressed = node.writer(COMPRESSED_TOPIC, COMPRESSED)
        assert images.wait_for_readers(2, DEADLINE) and info.wait_for_readers(1, DEADLINE)
        assert compressed.wait_for_readers(1, DEADLINE)
        for topic, _, profile in subscribe:  # best-effort readers drop what comes before they matched
            peer.wait_matched(topic, profile=profile)

        # What discovery told the peer of our writer: ROS's names, XCDR1, reliable, the typehash.
        [seen] = peer.of("matched", IMAGE_TOPIC, "default")[-1]["writers"]
        assert (seen["topic_name"], seen["type_name"]) == ("rt/cam0/image_raw", "sensor_msgs::msg::dds_::Image_")
        assert seen["user_data"] == f"typehash={idltypes.TYPE_HASHES[IMAGE]};"
        assert seen["xcdr1"] and not seen["xcdr2"] and seen["reliable"] and seen["has_type_id"]

        rng = np.random.default_rng(7)
        stamped = rng.integers(0, 256, (1024, 1360), np.uint8)
        write_stamp(stamped, 123_456_789)
        frames = [  # header, pixels, encoding, DDS source timestamp
            (cdr.Header(1_700_000_000, 1, "cam0"), stamped, "mono8"),
            (cdr.Header(1_700_000_000, 33_333_334, "cam0"), rng.integers(0, 256, (1024, 1360, 3), np.uint8), "rgb8"),
            (cdr.Header(1_700_000_001, 5, "cam0_odd"), rng.integers(0, 256, (5, 3), np.uint8), "mono8"),
            (cdr.Header.at(-1, ""), rng.integers(0, 65536, (7, 3), np.uint16), "mono16"),
        ]
        for i, (header, pixels, encoding) in enumerate(frames):
            images.write(cdr.encode_image_array(header, pixels, encoding, pad=True), timestamp_ns=1_800_000_000 + i)
        calibration = cdr.CameraInfo(
            cdr.Header(1_700_000_000, 1, "cam0"), 1024, 1360, "plumb_bob", [0.1, -0.2, 0.001, 0.002, 0.0],
            [1000.0, 0, 680, 0, 1000.0, 512, 0, 0, 1], [1.0, 0, 0, 0, 1, 0, 0, 0, 1],
            [1000.0, 0, 680, 0, 0, 1000, 512, 0, 0, 0, 1, 0], 1, 2, cdr.RegionOfInterest(1, 2, 3, 4, True),
        )  # fmt: skip
        info.write(cdr.encode_camera_info(calibration, pad=True))
        jpeg = bytes(rng.integers(0, 256, 12345, np.uint8))
        compressed.write(cdr.encode_compressed_image(frames[0][0], "jpeg", jpeg, pad=True))
        assert images.wait_for_acks(DEADLINE)

        # The reliable keep-last-10 subscriber gets every frame, in order; the best-effort one
        # may lose some (big frames, a 4 MiB socket buffer), so it is held to what it got.
        reliable = peer.wait_for_samples(IMAGE_TOPIC, len(frames), profile="default")
        best_effort = peer.wait_for_samples(IMAGE_TOPIC, 1, profile="sensor_data")
        assert [sample["stamp"] for sample in reliable] == [[h.sec, h.nanosec] for h, _, _ in frames]
        sent = {(h.sec, h.nanosec): (i, h, pixels, encoding) for i, (h, pixels, encoding) in enumerate(frames)}
        for sample in reliable + best_effort:
            i, header, pixels, encoding = sent[tuple(sample["stamp"])]
            assert (sample["frame_id"], sample["encoding"], sample["is_bigendian"]) == (header.frame_id, encoding, 0)
            assert (sample["height"], sample["width"], sample["step"]) == (*pixels.shape[:2], step_of(pixels))
            assert sample["size"] == pixels.nbytes
            assert sample["sha256"] == hashlib.sha256(pixels.tobytes()).hexdigest()
            assert sample["source_timestamp"] == 1_800_000_000 + i
        assert reliable[2]["head"] == frames[2][1].tobytes()[:16].hex()  # a 15-byte image: all of it
        assert read_stamp(stamp_rows(reliable[0])) == 123_456_789
        assert reliable[3]["stamp"] == [-1, 999_999_999]

        [got] = peer.wait_for_samples(INFO_TOPIC)
        assert (got["stamp"], got["frame_id"], got["height"], got["width"]) == ([1_700_000_000, 1], "cam0", 1024, 1360)
        assert (got["distortion_model"], got["d"], got["k"]) == ("plumb_bob", calibration.d, calibration.k)
        assert (got["r"], got["p"]) == (calibration.r, calibration.p)
        assert (got["binning"], got["roi"]) == ([1, 2], [1, 2, 3, 4, True])
        [got] = peer.wait_for_samples(COMPRESSED_TOPIC)
        assert (got["format"], got["size"], got["sha256"]) == ("jpeg", len(jpeg), hashlib.sha256(jpeg).hexdigest())
        assert (got["head"], got["tail"]) == (jpeg[:16].hex(), jpeg[-16:].hex())


def test_strings_reach_the_peer_padded_or_not(node, domain):
    with Peer(domain, {"/lab/error": "std_msgs/msg/String"}) as peer:
        writer = node.writer("/lab/error", "std_msgs/msg/String", dds.DEFAULT_SUBSCRIBER)
        assert writer.wait_for_readers(1, DEADLINE)
        texts = ["", "a", "héllo wörld", "x" * 1001]
        for text in texts:
            writer.write(cdr.encode_string(text))  # unpadded: the writer pads
        assert [sample["data"] for sample in peer.wait_for_samples("/lab/error", len(texts))] == texts


def test_the_peer_hands_over_whole_data_when_asked(node, domain):
    with Peer(domain, {COMPRESSED_TOPIC: COMPRESSED}, profile="sensor_data", with_data=True) as peer:
        writer = node.writer(COMPRESSED_TOPIC, COMPRESSED)
        assert writer.wait_for_readers(1, DEADLINE)
        peer.wait_matched(COMPRESSED_TOPIC)  # a best-effort reader drops what comes before it matched
        png = b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 3
        message = cdr.encode_compressed_image(cdr.Header.at(10**18 + 5, "cam0"), "png", png, pad=True)
        sample = peer.first_sample_of_resent(COMPRESSED_TOPIC, lambda: writer.write(message))  # best effort
        assert base64.b64decode(sample["data"]) == png
        assert (sample["stamp"], sample["frame_id"], sample["profile"]) == ([10**9, 5], "cam0", "sensor_data")


def test_header_requests_from_the_peer_are_read_and_decoded(node, domain):
    """The bridge's other direction: a ROS-like node publishes std_msgs/Header requests."""
    reader = node.header_reader("/cam0/frames_at")
    with Peer(domain, publish_headers=["/cam0/frames_at"]) as peer:
        requests = [(1000, 0, "cam0"), (-3, 999_999_999, "cell1/cam1"), (2**31 - 1, 1, "")]
        for sec, nanosec, frame_id in requests:
            peer.publish_header("/cam0/frames_at", sec, nanosec, frame_id)
        got: list[dds.ReceivedHeader] = []
        deadline = time.monotonic() + DEADLINE
        while len(got) < len(requests) and time.monotonic() < deadline:
            got += reader.wait(timeout=0.2)
        assert [(r.header.sec, r.header.nanosec, r.header.frame_id) for r in got] == requests
        assert reader.matched_count() == 1
        assert all(r.source_timestamp_ns > 0 for r in got)


# ------------------------------------------------------------------------------------ what ROS refuses


def test_a_reader_that_takes_only_xcdr2_never_matches_our_xcdr1_writer(node, domain):
    """ROS readers take only XCDR1. Were our writer to drift to XCDR2 (an @appendable type, a
    changed DATA_REPRESENTATION), this reader would match and every ROS reader would not."""
    with Peer(domain, [(IMAGE_TOPIC, IMAGE, "xcdr2"), (IMAGE_TOPIC, IMAGE, "default")]) as peer:
        writer = node.writer(IMAGE_TOPIC, IMAGE)
        assert writer.wait_for_readers(1, DEADLINE)  # the control reader
        wait_until(lambda: writer.incompatible_qos()[0] >= 1, DEADLINE, what="the XCDR2 reader refused")
        assert writer.incompatible_qos()[1] == dds.DATA_REPRESENTATION_QOS_POLICY_ID
        peer.wait_for(lambda _: bool(peer.of("incompatible_qos", IMAGE_TOPIC, "xcdr2")), what="refusal, peer side")
        assert (
            peer.of("incompatible_qos", IMAGE_TOPIC, "xcdr2")[-1]["policy_id"] == dds.DATA_REPRESENTATION_QOS_POLICY_ID
        )
        writer.write(cdr.encode_image_array(cdr.Header(9, 9, "x"), np.zeros((2, 3), np.uint8), "mono8", pad=True))
        peer.wait_for_samples(IMAGE_TOPIC, profile="default")  # the control got it: so would have the other
        assert writer.matched_count() == 1
        assert peer.samples(IMAGE_TOPIC, "xcdr2") == []
        assert all(event["current"] == 0 for event in peer.of("matched", IMAGE_TOPIC, "xcdr2"))


def test_a_best_effort_writer_is_refused_by_a_reliable_ros_subscriber(node, domain):
    """Why CAMERA_PUBLISHER is reliable: a default (reliable) ROS subscriber refuses a
    best-effort writer; only SensorData subscribers would see it."""
    with Peer(domain, [(IMAGE_TOPIC, IMAGE, "default"), (IMAGE_TOPIC, IMAGE, "sensor_data")]) as peer:
        writer = node.writer(IMAGE_TOPIC, IMAGE, dds.QosProfile(reliable=False, depth=2))
        assert writer.wait_for_readers(1, DEADLINE)  # the SensorData reader
        wait_until(lambda: writer.incompatible_qos()[0] >= 1, DEADLINE, what="the reliable reader refused")
        assert writer.incompatible_qos()[1] == dds.RELIABILITY_QOS_POLICY_ID
        peer.wait_for(lambda _: bool(peer.of("incompatible_qos", IMAGE_TOPIC, "default")), what="refusal, peer side")
        assert peer.of("incompatible_qos", IMAGE_TOPIC, "default")[-1]["policy_id"] == dds.RELIABILITY_QOS_POLICY_ID
        assert writer.matched_count() == 1
