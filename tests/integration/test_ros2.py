"""`fxis run --ros2` seen from the ROS 2 graph: a node in another process receives every topic
the bridge publishes and checks what it holds against the service's own record of each frame.

Each test runs against every setup of ``SETUPS``: the node is our own Cyclone participant
(tests/dds_peer) or a real rclpy node on Fast DDS in its default configuration (tests/rclpy_peer.py,
ROS 2 Kilted and Jazzy from their wheels); the bridge publishes through Cyclone (no ROS install)
or through rclpy (``--ros2-via rclpy``, Kilted's). Real nodes and their bridge share a network
namespace holding only loopback (tests.hosts.LoopbackNamespace): Fast DDS's default discovery
multicasts, and must reach nothing but them."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
from types import SimpleNamespace

import pytest

from fxis_shm import Client
from fxis_shm.core import timebase
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.stamp import read_stamp
from fxis_shm.service.launch import ServiceProcess
from tests.dds_peer import ROS_VENVS, Peer, domain_id, loopback_config, stamp_rows
from tests.hosts import Lab, LoopbackNamespace

from ..conftest import fxis, fxis_run_alone, wait_until
from .bags import read_bag
from .conftest import client_keys

pytestmark = pytest.mark.integration

NS = "/cell"
IMAGE, INFO, COMPRESSED, STRING = (
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CameraInfo",
    "sensor_msgs/msg/CompressedImage",
    "std_msgs/msg/String",
)
K = [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]
D = [0.1, -0.2, 0.001, 0.002, 0.0]
P = [500.0, 0.0, 320.0, 0.0, 0.0, 500.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0]
CALIBRATION = f"""image_width: 640
image_height: 480
camera_name: cam0
camera_matrix: {{rows: 3, cols: 3, data: {K}}}
distortion_model: plumb_bob
distortion_coefficients: {{rows: 1, cols: 5, data: {D}}}
rectification_matrix: {{rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}}
projection_matrix: {{rows: 3, cols: 4, data: {P}}}
"""
STAMP_TOLERANCE_NS = 100_000  # 0.1 ms: the two clocks read side by side, here and in the bridge
TUPLE_PERIOD_NS = 200_000_000  # the bridge's --ros2-tuples 5


# setup -> (the node's kind, how the bridge publishes)
SETUPS = {
    "cyclone-node": ("cyclone", "cyclone"),
    "fastdds-kilted-node,cyclone-bridge": ("kilted", "cyclone"),
    "fastdds-kilted-node,rclpy-bridge": ("kilted", "rclpy"),
    "fastdds-jazzy-node,cyclone-bridge": ("jazzy", "cyclone"),
}


@pytest.fixture(scope="module", params=SETUPS)
def bridge(request, tmp_path_factory):
    snapshots = tmp_path_factory.mktemp("snapshots")
    calibration = tmp_path_factory.mktemp("calibration") / "cam0.yaml"
    calibration.write_text(CALIBRATION)
    args = [
        "--camera",
        f"cam0=synthetic:width=640,height=480,fps=20,calibration={calibration},frame_id=cam0_optical",
        "--camera",
        "cam1=synthetic:width=320,height=240,fps=20,pixel_format=bgr8,phase_ms=7",
        "--slots",
        "100",
        "--ros2-tuples",
        "5",
        "--ros2-snapshots",
        str(snapshots),
        "--history",
        "5",  # the snapshot test's window reaches 3 s back: 2 s to spare when a loaded copy lags
    ]
    with running_bridge(request.param, args, tmp_path_factory, snapshots=snapshots) as running:
        yield running


@contextlib.contextmanager
def running_bridge(setup: str, args: list[str], tmp_path_factory, service: dict | None = None, **facts):
    """A service with ``args`` (and ServiceProcess's ``service`` options) and its bridge as
    ``setup`` says, and a Peer factory for its node."""
    service = service or {}
    peer_kind, via = SETUPS[setup]
    domain = domain_id()
    args = [*args, "--ros2", "--ros2-domain", str(domain), "--ros2-namespace", NS]
    if peer_kind == "cyclone":  # our own peer: Cyclone on 127.0.0.1, no multicast, no namespace
        with ServiceProcess(args, env={**os.environ, "CYCLONEDDS_URI": loopback_config()}, **service) as svc:
            yield SimpleNamespace(svc=svc, domain=domain, peer=peer_of(domain, "cyclone"), **facts)
        return
    args += ["--ros2-via", via]
    if via == "rclpy":
        args += ["--ros2-python", str(ROS_VENVS["kilted"] / "bin" / "python")]
    sockets = tmp_path_factory.mktemp("sockets")  # ipc endpoints: reachable from outside the namespace
    endpoints = {kind: f"ipc://{sockets}/{kind}" for kind in ("endpoint", "pub", "events")}
    env = {key: value for key, value in os.environ.items() if key != "CYCLONEDDS_URI"}  # Cyclone's defaults
    with (
        LoopbackNamespace() as host,
        ServiceProcess(args, env=env, wrapper=host.wrapper(), **endpoints, **service) as svc,
    ):
        yield SimpleNamespace(
            svc=svc,
            domain=domain,
            peer=peer_of(domain, peer_kind, host.wrapper()),
            udp_into_fastdds=via == "cyclone",  # datagrams into a Fast DDS node's default receive buffer
            **facts,
        )


def peer_of(domain: int, kind: str, wrapper=()):
    """A Peer factory for the setup: ``bridge.peer(topics, ...)``."""

    def peer(topics=(), **options) -> Peer:
        return Peer(domain, topics, kind=kind, wrapper=wrapper, **options)

    return peer


def capture_times(svc) -> dict[tuple[str, int], int]:
    """(camera, frame id) -> capture time in ROS time, from the service's own frame list."""
    with Client(svc.endpoint) as client:
        listing = client.frame_times()
    to_ros = timebase.offset("realtime", "monotonic")
    return {(camera, row[0]): row[1] + to_ros for camera, info in listing["cameras"].items() for row in info["frames"]}


def ns_of(sample: dict) -> int:
    sec, nanosec = sample["stamp"]
    return sec * 1_000_000_000 + nanosec


# reliable ("default") delivery of 300 kB frames at 20 fps judges a reader keeping up: in the
# parallel pass a Fast DDS node fed over UDP took 3 of cam0's frames in 15 s (make test run 17);
# it runs in the real-time tier, alone
@pytest.mark.parametrize("profile", ["sensor_data", pytest.param("default", marks=pytest.mark.realtime)])
def test_every_camera_topic_reaches_a_ros_reader_as_the_frames_were_captured(bridge, profile):
    topics = [
        (f"{NS}/cam0/image_raw", IMAGE),
        (f"{NS}/cam1/image_raw", IMAGE),
        (f"{NS}/cam0/camera_info", INFO),
        (f"{NS}/cam1/camera_info", INFO),
        (f"{NS}/cam1/image_raw/compressed", COMPRESSED),
    ]
    with bridge.peer(topics, profile=profile) as peer:
        for topic, _ in topics:
            peer.wait_matched(topic)
        for topic, _ in topics:
            peer.wait_for_samples(topic, 8)
        captured = capture_times(bridge.svc)
        images = {cam: peer.samples(f"{NS}/{cam}/image_raw") for cam in ("cam0", "cam1")}
        infos = {cam: {ns_of(s): s for s in peer.samples(f"{NS}/{cam}/camera_info")} for cam in ("cam0", "cam1")}
        compressed = peer.samples(f"{NS}/cam1/image_raw/compressed")

    layouts = {"cam0": (480, 640, "mono8", 640, "cam0_optical"), "cam1": (240, 320, "bgr8", 960, "cam1")}
    for cam, samples in images.items():
        height, width, encoding, step, frame_id = layouts[cam]
        ids = []
        for sample in samples:
            assert (sample["height"], sample["width"], sample["encoding"], sample["step"]) == (
                height,
                width,
                encoding,
                step,
            )
            assert sample["size"] == height * step and sample["is_bigendian"] == 0 and sample["frame_id"] == frame_id
            frame = read_stamp(stamp_rows(sample))
            assert frame is not None, "the pixels are not a whole frame of the synthetic camera"
            ids.append(frame)
            if (cam, frame) in captured:
                assert abs(ns_of(sample) - captured[(cam, frame)]) <= STAMP_TOLERANCE_NS
            info = infos[cam].get(ns_of(sample))
            if info is not None:
                assert (info["height"], info["width"], info["frame_id"]) == (height, width, frame_id)
        assert sum((cam, i) in captured for i in ids) >= 4, "too few received frames are still in the ring"
        assert set(ns_of(s) for s in samples) & set(infos[cam]), "no camera_info with its image's stamp"
        if profile == "default" and not getattr(bridge, "udp_into_fastdds", False):
            assert ids == list(range(ids[0], ids[0] + len(ids)))  # reliable: every frame stored, in order
        elif profile == "default":
            # Cyclone's UDP into Fast DDS's 208 KiB buffer, on a machine running the suite on both
            # cores: a repair can come too late for the writer's history (gaps of 1-12 frames seen
            # under the full suite). Whole frames in order is the guard against type information
            # or buffer overrun blocking the node (it got 0 images before). docs/ros2.md.
            assert ids == sorted(set(ids)), ids
    assert infos["cam0"] and all(s["k"] == K and s["d"] == D and s["p"] == P for s in infos["cam0"].values())
    assert all(s["distortion_model"] == "plumb_bob" for s in infos["cam0"].values())
    assert all(s["k"] == [0.0] * 9 for s in infos["cam1"].values())  # no calibration: size only
    assert all(s["format"] == "bgr8; jpeg compressed bgr8" and s["head"].startswith("ffd8") for s in compressed)


def test_tuple_topics_carry_one_stamp_per_tuple_the_middle_of_its_captures(bridge):
    topics = [
        (f"{NS}/tuple/{cam}/{kind}", t)
        for cam in ("cam0", "cam1")
        for kind, t in (("image_raw", IMAGE), ("camera_info", INFO))
    ]
    with bridge.peer(topics) as peer:
        for topic, _ in topics:
            peer.wait_for_samples(topic, 6)
        captured = capture_times(bridge.svc)
        by_camera = {
            cam: {ns_of(s): s for s in peer.samples(f"{NS}/tuple/{cam}/image_raw")} for cam in ("cam0", "cam1")
        }
        info_stamps = {ns_of(s) for s in peer.samples(f"{NS}/tuple/cam0/camera_info")}
    common = sorted(set(by_camera["cam0"]) & set(by_camera["cam1"]))
    assert len(common) >= 4, "the cameras' tuple images do not share stamps (ExactTime could not group them)"
    assert info_stamps & set(common)
    checked = 0
    for stamp in common:
        frames = {cam: read_stamp(stamp_rows(by_camera[cam][stamp])) for cam in by_camera}
        times = [captured.get((cam, frame)) for cam, frame in frames.items()]
        if None not in times:
            assert abs(stamp - (min(times) + max(times)) // 2) <= STAMP_TOLERANCE_NS
            checked += 1
    assert checked >= 2
    # One tuple per schedule time, 200 ms apart, each stamped near its time; a camera's worker
    # held up past the wait's slack moves one tuple's stamp back to its frames from before the
    # stall (CI, stop 53: two stamps under 150 ms apart). So judged over every run of tuples:
    # k + 1 of them span at least k - 1 periods (at 20 Hz, 3 would span 100 ms).
    spans = [(k, common[i + k] - common[i]) for k in range(2, len(common)) for i in range(len(common) - k)]
    assert all(span >= (k - 1) * TUPLE_PERIOD_NS for k, span in spans), f"more than 5 tuples a second: {common}"


@pytest.mark.parametrize("bridge", ["cyclone-node"], indirect=True)  # the bridge's own stream, whatever reads it
def test_a_camera_held_up_past_its_period_repeats_no_tuple(bridge):
    """cam0's worker stopped: every tuple asked for meanwhile is made of its frames from before
    the stall, the same tuple; it is published once (ExactTime would get the same images twice
    under one stamp), the repeats counted skipped."""
    topic = f"{NS}/tuple/cam0/image_raw"
    with Client(bridge.svc.endpoint) as client:
        status = client.status()
        worker, skipped = status["supervisor"]["processes"]["camera:cam0"]["pid"], status["ros2"]["tuples"]["skipped"]
        with bridge.peer([(topic, IMAGE)]) as peer:
            peer.wait_for_samples(topic, 1)
            os.kill(worker, signal.SIGSTOP)
            try:
                wait_until(
                    lambda: client.status()["ros2"]["tuples"]["skipped"] > skipped,
                    what="a tuple asked for while cam0 was held up counted skipped",
                )
            finally:
                os.kill(worker, signal.SIGCONT)
            peer.wait_for_samples(topic, len(peer.samples(topic)) + 2)
            stamps = [ns_of(s) for s in peer.samples(topic)]
    assert stamps == sorted(set(stamps)), "a tuple was published twice, or out of order"


def frames_at_peer(bridge, names, with_errors=()):
    topics = [(f"{NS}/frames_at/{name}/{cam}/image_raw", IMAGE) for name in names for cam in ("cam0", "cam1")]
    topics += [(f"{NS}/frames_at/{name}/error", STRING) for name in with_errors]
    topics += [(f"{NS}/frames_at/error", STRING)]
    return requester(bridge, topics, f"{NS}/frames_at")


@contextlib.contextmanager
def requester(bridge, topics, request_topic, kind="publish_headers"):
    """A peer that will publish requests on ``request_topic``, once both ends matched: as with a
    ROS service's wait_for_service, since a DDS writer may see its match before the reader does,
    and a volatile reader never gets what was written before it knew the writer (seen with
    Jazzy's Fast DDS 2.14: its first request reached the bridge before its discovery did)."""
    with bridge.peer(topics, **{kind: [request_topic]}) as peer, bridge.svc.client() as client:

        def matched():
            topics = (client.status().get("ros2") or {}).get("topics", {})
            return topics.get(request_topic, {}).get("matched", 0) >= 1

        wait_until(matched, what=f"the bridge's reader of {request_topic} matching the peer's writer")
        yield peer


def ask(peer, t_ros: int, name: str) -> None:
    peer.publish_header(f"{NS}/frames_at", *divmod(t_ros, 1_000_000_000), name)


def nearest(captured: dict, cam: str, t: int) -> int:
    return min((abs(time - t), frame) for (c, frame), time in captured.items() if c == cam)[1]


def test_frames_at_a_past_and_a_near_future_t_star_from_two_requesters_at_once(bridge):
    with frames_at_peer(bridge, ["robot1", "arm/left"]) as peer:
        now = timebase.reader("realtime")()
        past, future = now - 400_000_000, now + 300_000_000
        ask(peer, past, "robot1")
        ask(peer, future, "arm/left")
        for name in ("robot1", "arm/left"):
            for cam in ("cam0", "cam1"):
                peer.wait_for_samples(f"{NS}/frames_at/{name}/{cam}/image_raw", 1)
        captured = capture_times(bridge.svc)
        for name, t_star in (("robot1", past), ("arm/left", future)):
            for cam in ("cam0", "cam1"):
                (sample,) = peer.samples(f"{NS}/frames_at/{name}/{cam}/image_raw")
                frame = read_stamp(stamp_rows(sample))
                assert abs(ns_of(sample) - captured[(cam, frame)]) <= STAMP_TOLERANCE_NS  # its own capture time
                # the joint selection's pick: the nearest frame, or its neighbour for a smaller skew
                assert abs(frame - nearest(captured, cam, t_star)) <= 1
        assert not peer.samples(f"{NS}/frames_at/error")


def test_frames_at_refuses_bad_requests_with_a_reason_and_keeps_serving(bridge):
    with frames_at_peer(bridge, ["ok"], with_errors=["late", "epoch"]) as peer:
        now = timebase.reader("realtime")()
        # A good request first, asked again until answered: then the bridge's reader knows this
        # peer's writer. requester() counts the matches of the module's bridge, and a writer of the
        # previous test's peer counts until DDS drops it: make test runs 56 and 63 lost the first
        # request here, published before this peer's own writer had matched.
        peer.first_sample_of_resent(
            f"{NS}/frames_at/ok/cam0/image_raw", lambda: ask(peer, now - 200_000_000, "ok"), every=3.0
        )
        ask(peer, now - 3600 * 1_000_000_000, "late")  # an hour ago: outside any history
        ask(peer, 1, "epoch")  # 1970: before the service clock (CLOCK_MONOTONIC) began
        ask(peer, now, "not a name!")
        (late,) = peer.wait_for_samples(f"{NS}/frames_at/late/error", 1)
        (epoch,) = peer.wait_for_samples(f"{NS}/frames_at/epoch/error", 1)
        (bad,) = peer.wait_for_samples(f"{NS}/frames_at/error", 1)
    assert late["data"].startswith("OUT_OF_RANGE")
    assert re.fullmatch(r"OUT_OF_RANGE: t\* lies [0-9.]+ s before the service clock began", epoch["data"])
    assert "not a name!" in bad["data"]
    with Client(bridge.svc.endpoint) as client:  # the bridge reports its counters once a second

        def counted():
            counts = client.status()["ros2"]["frames_at"]
            return counts["refused"] >= 3 and counts["published"] >= 1

        wait_until(counted, what="the refused and answered requests in the service's status")


@pytest.mark.parametrize("bridge", ["cyclone-node"], indirect=True)  # only our own peer can ask for XCDR2
def test_a_reader_that_asks_for_xcdr2_only_is_not_matched_as_a_ros_reader_would_not_be(bridge):
    topic = f"{NS}/cam0/image_raw"
    with bridge.peer([(topic, IMAGE, "xcdr2"), (topic, IMAGE, "default")]) as peer:
        peer.wait_for(lambda _: peer.of("incompatible_qos", topic, "xcdr2"), what="the XCDR2 reader's refusal")
        peer.wait_for_samples(topic, 5, profile="default")  # the XCDR2 reader had as long
        assert peer.samples(topic, profile="xcdr2") == []
    assert peer.of("incompatible_qos", topic, "xcdr2")[-1]["policy_id"] == 25  # DATA_REPRESENTATION
    # nothing silent: the bridge's side says so too, in fxis status and its log
    with bridge.svc.client() as client:

        def refused():
            return ((client.status().get("ros2") or {}).get("topics") or {}).get(topic, {}).get("refused", 0) >= 1

        wait_until(refused, what="the refused reader in the bridge's status")
    status = fxis("status", "--endpoint", bridge.svc.endpoint)
    assert f"{topic}: " in status.stdout and "could not match: 1 with an incompatible DATA_REPRESENTATION QoS" in (
        status.stdout
    ), status.stdout


# A bridge on Cyclone reaches Fast DDS nodes over UDP, repairing what their 208 KiB receive buffer
# drops: a reliable reader beside a stopped one then lost frames under load (docs/ros2.md, "Which
# way"). On one host that is the rclpy path's job, which this claims; Cyclone nodes, either way.
# Real time: "no frame lost" holds while the reader gets the CPU at 20 fps; a reader descheduled
# longer than the writer's history (the parallel pass, 2 cores) loses frames, as DDS says it may.
@pytest.mark.realtime
@pytest.mark.parametrize("bridge", ["cyclone-node", "fastdds-kilted-node,rclpy-bridge"], indirect=True)
def test_a_reader_that_stops_reading_holds_up_neither_the_cameras_nor_another_reader(bridge):
    topic = f"{NS}/cam0/image_raw"
    with Client(bridge.svc.endpoint) as client:
        dropped = client.status()["cameras"]["cam0"]["frames_dropped"]
    with bridge.peer([(topic, IMAGE)]) as stuck, bridge.peer([(topic, IMAGE)]) as reader:
        stuck.wait_for_samples(topic, 1)
        os.kill(stuck.proc.pid, signal.SIGSTOP)
        try:
            before = len(reader.wait_for_samples(topic, 1))
            received = reader.wait_for_samples(topic, before + 40)  # 2 s of frames at 20 fps
        finally:
            os.kill(stuck.proc.pid, signal.SIGCONT)
    ids = [read_stamp(stamp_rows(s)) for s in received]
    with Client(bridge.svc.endpoint) as client:
        status = client.status()
    assert ids == list(range(ids[0], ids[0] + len(ids))), f"the reading subscriber lost frames: {status['ros2']}"
    assert status["cameras"]["cam0"]["frames_dropped"] == dropped
    assert status["ros2"]["cameras"]["cam0"]["skipped"] == 0


@pytest.mark.parametrize(
    "args, message",
    [
        (["--camera", "cam-0=synthetic"], "cam-0"),
        (["--ros2-namespace", "/bad//ns"], "ros2_namespace"),
        (["--ros2-domain", "300"], "ros2_domain"),
        (["--ros2-tuples", "0"], "ros2_tuples"),
        (["--camera", "a=synthetic:calibration=/nonexistent.yaml"], "calibration"),
    ],
)
def test_settings_ros_cannot_carry_stop_the_start_with_a_clear_message(args, message):
    result = fxis_run_alone("--ros2", *args)
    assert result.returncode == 2
    assert message in result.stderr and "Traceback" not in result.stderr


def test_a_snapshot_asked_for_on_the_snapshot_topic_keeps_the_window_in_ros_time(bridge):
    result = f"{NS}/snapshot/result"
    with bridge.svc.client() as client:  # the window starts 3 s back: the service must have run that long
        wait_until(lambda: client.status()["cameras"]["cam0"]["frames_stored"] > 60, what="3 s of frames stored")
    with requester(bridge, [(result, STRING)], f"{NS}/snapshot") as peer:
        t = timebase.reader("realtime")() - 1_000_000_000  # an event a second ago, in ROS time
        peer.publish_header(f"{NS}/snapshot", *divmod(t, 1_000_000_000), "grasp_17")
        peer.publish_header(f"{NS}/snapshot", *divmod(t, 1_000_000_000), "bad name")
        answers = [json.loads(s["data"]) for s in peer.wait_for_samples(result, 2, timeout=20)]
    by_name = {a["name"]: a for a in answers}
    assert "error" in by_name["bad name"] and "frame_id must name the bag" in by_name["bad name"]["error"]
    kept = by_name["grasp_17"]
    assert kept["bag"] == str(bridge.snapshots / "grasp_17")
    with bridge.svc.client() as client:  # frames missing only where the camera itself fell behind
        dropped = {name: s["frames_dropped"] for name, s in client.status()["cameras"].items()}
    assert all(len(c["missing"]) <= dropped[name] for name, c in kept["cameras"].items()), (kept, dropped)
    bag = read_bag(bridge.snapshots / "grasp_17")
    stamps = [m.stamp for m in bag.messages["/cam0/image_raw"]]
    assert len(stamps) >= 55 and t - 2_000_000_000 <= stamps[0] and stamps[-1] <= t + 1_000_000_000


@pytest.mark.parametrize(
    "bridge",
    ["fastdds-kilted-node,cyclone-bridge", "fastdds-kilted-node,rclpy-bridge", "fastdds-jazzy-node,cyclone-bridge"],
    indirect=True,
)
def test_the_bridge_is_a_ros_node_and_publishes_each_cameras_diagnostics(bridge):
    node = ("fxis_" + bridge.svc.name.replace("-", "_"), NS)
    with bridge.peer([("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")]) as peer:
        wait_until(lambda: node in peer.nodes(), what=f"the bridge's node {node} in the node list")
        peer.wait_for_samples("/diagnostics", 7, timeout=20)  # once a second; the window fills in 5 s
        last = peer.samples("/diagnostics")[-1]
    by_name = {s["name"]: s for s in last["status"]}
    assert set(by_name) == {f"fxis {bridge.svc.name}: cam0", f"fxis {bridge.svc.name}: cam1"}
    for status in by_name.values():
        values = status["values"]
        assert status["hardware_id"] == "synthetic" and values["worker"] == "running"
        assert values["rate_configured_hz"] == "20" and values["restarts"] == "0"
        # measured over its window, not the configured rate copied: the camera stores 20 a second
        assert 15.0 <= float(values["rate_measured_hz"]) <= 25.0, values
        assert float(values["newest_frame_age_ms"]) < 1000.0
        assert status["level"] in (0, 1) and (status["level"] == 0) == (status["message"] == "streaming")


def test_a_fastdds_node_on_another_host_gets_whole_frames_in_order_from_a_bridge_without_ros():
    """A camera PC without ROS (the bridge on Cyclone) and a Kilted node on another emulated host
    (its own network, clock and /dev/shm, behind a 1 Gbit link), in its default configuration:
    Fast DDS's multicast discovery across the link, images over UDP into its default buffer.
    Quiet, it gets every frame; with the suite on 4 workers loading both cores, 2 of 40 once
    came too late for repair, as on one host (docs/ros2.md): whole frames, in order."""
    topic = f"{NS}/cam0/image_raw"
    domain = domain_id()
    with Lab() as lab:
        host = lab.host(clock_offset_s=1000, rate="1gbit")
        subprocess.run(["ip", "-n", host.netns, "route", "add", "224.0.0.0/4", "dev", host.inner_link], check=True)
        cyclone = (
            '<CycloneDDS xmlns="https://cdds.io/config"><Domain Id="any"><General><Interfaces>'
            f'<NetworkInterface name="{host.link}" multicast="true"/></Interfaces>'
            "<AllowMulticast>true</AllowMulticast></General></Domain></CycloneDDS>"
        )
        args = ["--camera", "cam0=synthetic:width=640,height=480,fps=20", "--ros2", "--ros2-via", "cyclone"]
        args += ["--ros2-domain", str(domain), "--ros2-namespace", NS]
        with ServiceProcess(args, env={**os.environ, "CYCLONEDDS_URI": cyclone}) as svc:
            with Peer(domain, [(topic, IMAGE)], kind="kilted", wrapper=host.wrapper()) as peer:
                samples = peer.wait_for_samples(topic, 40, timeout=30)  # 2 s of frames
            with svc.client() as client:
                matched = client.status()["ros2"]["topics"][topic]
    ids = [read_stamp(stamp_rows(s)) for s in samples]
    assert None not in ids and ids == sorted(set(ids)) and ids[-1] - ids[0] < 2 * len(ids), ids
    assert matched["refused"] == 0


@pytest.mark.parametrize(
    "bridge", ["fastdds-kilted-node,cyclone-bridge", "fastdds-kilted-node,rclpy-bridge"], indirect=True
)
def test_a_ros_node_reads_and_changes_a_cameras_settings_on_the_settings_topics(bridge):
    result = f"{NS}/settings/result"
    with requester(bridge, [(result, STRING)], f"{NS}/settings", "publish_strings") as peer:
        peer.publish_string(f"{NS}/settings", json.dumps({"id": 1, "camera": "cam0"}))
        peer.publish_string(f"{NS}/settings", json.dumps({"id": 2, "camera": "cam0", "set": {"gain": 6}}))
        peer.publish_string(f"{NS}/settings", json.dumps({"id": 3, "camera": "cam0", "set": {"nonsense": 1}}))
        peer.publish_string(f"{NS}/settings", "not json")
        answers = {a.get("id"): a for a in (json.loads(s["data"]) for s in peer.wait_for_samples(result, 4))}
    assert answers[1]["camera"] == "cam0" and "gain" in answers[1]["values"]
    assert answers[2]["changed"] == {"gain": 6.0} and answers[2]["cost"] == "live"
    assert "nonsense" in answers[3]["error"]
    assert "not JSON" in answers[None]["error"]
    with bridge.svc.client() as client:  # the change took, in the service itself
        assert client.settings("cam0")["values"]["gain"] == 6.0
        client.configure("cam0", gain=0)  # the module's service, as the other tests found it


@pytest.mark.parametrize("allow", [False, True], ids=["operators", "operators,ros2-settings-allow"])
def test_under_operators_a_node_without_a_key_changes_settings_only_where_allowed(allow, keys, tmp_path_factory):
    """Issue 42, finding 2: a bare rclpy node (DDS carries no key) changed settings while an
    authenticated non-operator got FORBIDDEN. Now the bridge only reads under --curve-operators,
    unless --ros2-settings allow."""
    folder, allowed = keys
    operators = tmp_path_factory.mktemp("operators")
    assert fxis("keys", "--out", str(operators), "--name", "operator").returncode == 0
    args = ["--camera", "cam0=synthetic:width=320,height=240,fps=20"]
    args += ["--curve-secret", str(folder / "server.key_secret"), "--curve-clients", str(allowed)]
    args += ["--curve-operators", str(operators), *(["--ros2-settings", "allow"] if allow else [])]
    setup = "fastdds-kilted-node,rclpy-bridge"  # a real rclpy node, a real rclpy bridge
    alice = client_keys(folder, "alice")  # let in, no operator
    with running_bridge(setup, args, tmp_path_factory, service={"client_keys": alice}) as bridge:
        result = f"{NS}/settings/result"
        with requester(bridge, [(result, STRING)], f"{NS}/settings", "publish_strings") as peer:
            peer.publish_string(f"{NS}/settings", json.dumps({"id": 1, "camera": "cam0"}))
            peer.publish_string(f"{NS}/settings", json.dumps({"id": 2, "camera": "cam0", "set": {"gain": 6}}))
            answers = {a.get("id"): a for a in (json.loads(s["data"]) for s in peer.wait_for_samples(result, 2))}
        assert "gain" in answers[1]["values"]  # reading is open, as over ZeroMQ
        with bridge.svc.client() as client:
            gain = client.settings("cam0")["values"]["gain"]
        if allow:
            assert answers[2]["changed"] == {"gain": 6.0} and gain == 6.0
        else:
            assert "--ros2-settings allow" in answers[2]["error"] and "changed" not in answers[2]
            assert gain == 0.0


@pytest.mark.parametrize("bridge", ["cyclone-node", "fastdds-kilted-node,rclpy-bridge"], indirect=True)
def test_a_snapshot_asked_for_on_a_codec_topic_keeps_the_window_as_video(bridge):
    from .test_record_video import decoded

    result, request = f"{NS}/snapshot/result", f"{NS}/snapshot/h264"
    with bridge.svc.client() as client:  # the window starts 3 s back; 2 s of it stored at least
        wait_until(lambda: client.status()["cameras"]["cam1"]["frames_stored"] > 40, what="2 s of frames stored")
    with requester(bridge, [(result, STRING)], request) as peer:
        t = timebase.reader("realtime")() - 1_000_000_000  # an event a second ago, in ROS time
        peer.publish_header(request, *divmod(t, 1_000_000_000), "grasp_18")
        (answer,) = [json.loads(s["data"]) for s in peer.wait_for_samples(result, 1, timeout=20)]
    assert answer["name"] == "grasp_18" and answer["encoding"] == "h264", answer
    # the answer says what the snapshot kept of each camera: a bag of None kept nothing (make test
    # run 41 found no bag here once, unexplained: this shows why next time)
    assert answer["bag"] == str(bridge.snapshots / "grasp_18"), answer
    bag = read_bag(bridge.snapshots / "grasp_18")
    assert bag.custom_data["encoding"] == "h264"
    for cam, pixels in (("cam0", "gray"), ("cam1", "bgr24")):
        video, frames = bag.messages[f"/{cam}/video"], bag.messages[f"/{cam}/video/frames"]
        assert len(video) == answer["cameras"][cam]["frames"] > 0 and frames[0].msg.keyframe
        stamps = [rosmsgs.stamp_ns(m.msg.timestamp) for m in video]
        assert t - 2_000_000_000 <= stamps[0] and stamps[-1] <= t + 1_000_000_000  # the window, in ROS time
        assert [read_stamp(image) for _, image in decoded(video, pixels)] == [f.msg.frame_id for f in frames]


TRIGGER_LATENCY_NS = 3_000_000  # the synthetic camera's modelled trigger latency
LATENCY_NOISE_NS = 500_000  # what the learned latency may miss by (tests/integration/test_capture_at.py)


@pytest.fixture(params=["cyclone-node", "fastdds-kilted-node,rclpy-bridge"])
def triggered_bridge(request, tmp_path_factory):
    """A service with a camera that can be triggered and a free-running one, and its bridge
    (the module's cameras all run free)."""
    args = ["--camera", "trig=synthetic:trigger=software,trigger_latency_ms=3,width=64,height=48"]
    args += ["--camera", "free=synthetic:fps=20,width=64,height=48"]
    with running_bridge(request.param, args, tmp_path_factory) as running:
        yield running


# Real time: it judges a real timer's residual against that timer's p99 lateness, which one
# trigger in a hundred passes by definition, and more of them beside the parallel pass
@pytest.mark.realtime
def test_frames_at_capture_triggers_the_camera_for_t_star_and_says_how_each_frame_was_captured(triggered_bridge):
    name, request = "robot1", f"{NS}/frames_at/capture"
    topics = [(f"{NS}/frames_at/{name}/{cam}/image_raw", IMAGE) for cam in ("trig", "free")]
    topics += [(f"{NS}/frames_at/{name}/capture", STRING), (f"{NS}/frames_at/{name}/error", STRING)]
    asked = []
    with requester(triggered_bridge, topics, request) as peer:
        for n in range(1, 4):  # one after the other: each reply's JSON follows its own images
            t_star = timebase.reader("realtime")() + 300_000_000  # ahead enough for a loaded machine
            peer.publish_header(request, *divmod(t_star, 1_000_000_000), name)
            peer.wait_for_samples(f"{NS}/frames_at/{name}/capture", n)
            asked.append(t_star)
        peer.publish_header(request, *divmod(asked[0], 1_000_000_000), name)  # now in the past
        (error,) = peer.wait_for_samples(f"{NS}/frames_at/{name}/error", 1)
        replies = [json.loads(s["data"]) for s in peer.samples(f"{NS}/frames_at/{name}/capture")]
        images = {cam: peer.samples(f"{NS}/frames_at/{name}/{cam}/image_raw") for cam in ("trig", "free")}
    with triggered_bridge.svc.client() as client:
        sync = client.status()["cameras"]["trig"]["sync"]
    late_max = sync["timer_late_p99_ms"] * 1_000_000
    assert error["data"].startswith("OUT_OF_RANGE") and "past" in error["data"]
    assert [r["t_target"] for r in replies] == asked
    for n, (reply, trig_image, free_image) in enumerate(zip(replies, images["trig"], images["free"])):
        trig, free = reply["cameras"]["trig"], reply["cameras"]["free"]
        assert trig["capture"] == ("late" if abs(trig["residual_ns"]) > 2_000_000 else "scheduled")  # tolerance
        assert free["capture"] == "free" and free["residual_ns"] is None
        assert abs(ns_of(trig_image) - trig["t_capture"]) <= STAMP_TOLERANCE_NS  # the image is that frame
        assert abs(ns_of(free_image) - free["t_capture"]) <= STAMP_TOLERANCE_NS
        # the residual as the service measured it, and the frame captured at T: late by at most
        # what the worker's timer was late (and, on the first trigger, the latency not learned
        # yet), early by no more than the learned latency's noise
        assert abs(trig["t_capture"] - reply["t_target"] - trig["residual_ns"]) <= STAMP_TOLERANCE_NS
        unlearned = TRIGGER_LATENCY_NS if n == 0 else 0
        assert -LATENCY_NOISE_NS <= trig["residual_ns"] <= late_max + unlearned + LATENCY_NOISE_NS
