"""The ``bag`` camera: a recorded bag replayed by a real service, checked against the bag."""

import cv2
import numpy as np
import pytest

from fxis_shm import Client, read_stamp
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.stamp import write_stamp
from fxis_shm.formats.videochoice import DEFAULT_CRF, Choice
from fxis_shm.formats.videodecoder import COLOUR, MONO, TrackDecoder, pixels_of
from fxis_shm.formats.videoencoder import StreamEncoder
from fxis_shm.formats.videotracks import VideoSettings
from fxis_shm.service.launch import ServiceProcess
from fxis_shm.workers.backends.bag import LEAD_NS, BagCamera

from ..conftest import fxis, fxis_run_alone, wait_until
from ..integration.bags import CAMERAS, read_bag, record, start_cameras, stop
from ..virtualtime.clock import VirtualClock

pytestmark = pytest.mark.integration
# A bag played once plays for over 2 s, longer than a loaded machine holds a worker up (up to
# 1.5 s): a worker held up past a frame's interval drops it (counted), and a bag played in
# half a second could lose every frame, leaving none to check


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Two seconds of a two-camera cell (left mono8, right bgr8, 20 fps), and what rosbags reads of it."""
    tmp = tmp_path_factory.mktemp("cell")
    svc = start_cameras(tmp / "service.log")
    try:
        record(svc, tmp / "bag", "--seconds", "2")
    finally:
        stop(svc)
    bag = read_bag(tmp / "bag")
    stamps = {
        cam: {read_stamp(rosmsgs.image_array(m.msg)): m.stamp for m in bag.messages[f"/{cam}/image_raw"]}
        for cam in ("left", "right")
    }
    return str(tmp / "bag"), stamps


def bag_cameras(path, extra=""):
    return [
        "--camera",
        f"left=bag:path={path},topic=/left/image_raw{extra}",
        "--camera",
        f"right=bag:path={path},topic=/right/image_raw{extra}",
    ]


def replayed(client, count: int, cameras=("left", "right")) -> None:
    """Waits until every camera has stored ``count`` frames."""
    wait_until(
        lambda: all((client.status()["cameras"][c].get("frames_stored") or 0) >= count for c in cameras),
        timeout=30,
        what=f"{count} frames replayed",
    )


def paired_run(client, count: int) -> int | None:
    """The capture time of the newest left frame that ends ``count`` left frames in a row (as
    stored) whose partners right stored too, or None. Frames of one bag time play at one time
    (workers/backends/bag.py), so a partner is a right frame of the same capture time.

    Why: a worker held up past a frame interval (50 ms here) drops that frame, counted, to stay
    in step, and a tuple whose partner was dropped pairs the least skewed neighbour instead: the
    tuples asked for are of frames both cameras stored, whatever the load."""
    times = client.frame_times(["left", "right"])
    column = times["columns"].index("t_capture")
    left, right = ([row[column] for row in times["cameras"][cam]["frames"]] for cam in ("left", "right"))
    partners, run, newest = set(right), 0, None
    for t in left:
        run = run + 1 if t in partners else 0
        if run >= count:
            newest = t
    return newest


def paired_tuples(client, count: int) -> list:
    """``count`` consecutive tuples of frames both cameras stored (paired_run): those before the
    newest such run's end, which are that run's."""
    end = wait_until(
        lambda: paired_run(client, count), timeout=30, what=f"{count} frames in a row stored by both cameras"
    )
    tuples = client.sequence("consecutive", cameras=["left", "right"], count=count, at=end)
    assert tuples[-1]["left"].t_capture == end
    return tuples


def assert_recorded_spacing(tuples, recorded: list[int], all_recorded) -> None:
    """Consecutive tuples played as far apart as their frames were recorded (at ``recorded``):
    play time minus recorded stamp is the same for each, to rounding. The bag loops, and the
    tuples may span its end: a later pass plays a loop later, more than the recorded span."""
    span = max(all_recorded) - min(all_recorded)
    offsets = [t["left"].t_capture - stamp for t, stamp in zip(tuples, recorded)]
    for a, b in zip(offsets, offsets[1:]):
        assert abs(b - a) <= 1_000 or b - a > span, offsets  # ns: rounding only, or the next pass


def recorded_gap(stamps, a, b) -> int:
    """The recorded time between the frames whose pixels two replayed frames show."""
    return stamps[a.camera][read_stamp(b.image)] - stamps[a.camera][read_stamp(a.image)]


def test_tuples_of_a_replayed_bag_are_the_recorded_frames_at_the_recorded_spacing(start_service, recorded):
    path, stamps = recorded
    svc = start_service(*bag_cameras(path), "--slots", "64")
    with svc.client(timeout=5) as client:
        tuples = paired_tuples(client, 10)
    for t in tuples:
        ids = {cam: read_stamp(f.image) for cam, f in t.items()}
        assert ids["left"] in stamps["left"] and ids["left"] == ids["right"]  # recorded together, replayed together
        assert t["left"].image.shape == (120, 160) and t["right"].image.shape == (120, 160, 3)
        assert t.skew_ns == 0
    recorded = [stamps["left"][read_stamp(t["left"].image)] for t in tuples]
    assert_recorded_spacing(tuples, recorded, stamps["left"].values())


def test_speed_scales_the_spacing(start_service, recorded):
    path, stamps = recorded
    svc = start_service(*bag_cameras(path, ",speed=2"))
    with svc.client(timeout=5) as client:
        replayed(client, 6)
        a, b = client.sequence("consecutive", camera="left", count=2)
    assert abs((b.t_capture - a.t_capture) - recorded_gap(stamps, a, b) / 2) <= 1_000  # twice as fast


def test_stamps_recorded_keeps_the_recorded_stamps(start_service, recorded):
    path, stamps = recorded
    svc = start_service(*bag_cameras(path, ",stamps=recorded"))
    with svc.client(timeout=5) as client:
        replayed(client, 2)
        frame = client.latest(["left"])["left"]
        assert frame.t_capture == stamps["left"][read_stamp(frame.image)]  # yesterday's stamp, as recorded
        # asked for by a recorded time, it is found there
        again = client.image("left", at=frame.t_capture, wait="none")
        assert read_stamp(again.image) == read_stamp(frame.image)


def test_a_bag_played_once_ends_after_its_last_frame_and_says_so(start_service, recorded):
    path, stamps = recorded
    svc = start_service("--camera", f"v=bag:path={path},topic=/left/image_raw,loop=false", "--slots", "64")
    with svc.client(timeout=5) as client:
        status = wait_until(
            lambda: (s := client.status()["cameras"]["v"])["note"] and s, timeout=30, what="the end of the bag"
        )
        assert "end of bag" in status["note"]
        assert status["frames_stored"] + status["frames_dropped"] == len(stamps["left"])
        first = client.sequence("consecutive", camera="v", count=status["frames_stored"])
    # every frame stored is a recorded one, in the recorded order; the others were counted as
    # dropped (a loaded machine may make the worker drop late frames): with none dropped, all
    played = [read_stamp(f.image) for f in first]
    assert len(played) == status["frames_stored"]
    assert set(played) <= set(stamps["left"]) and played == sorted(set(played)), played


def test_a_jpeg_bag_replays_decoded(start_service, recorded, tmp_path):
    svc_log = tmp_path / "svc.log"
    cell = start_cameras(svc_log)
    try:
        record(cell, tmp_path / "j", "--frames", "10", "--encoding", "jpeg", "--cameras", "right")
    finally:
        stop(cell)
    bag = read_bag(tmp_path / "j")
    (topic,) = bag.topics
    assert topic == "/right/image_raw/compressed"
    recorded_ids = [
        read_stamp(cv2.imdecode(np.frombuffer(bytes(m.msg.data), np.uint8), cv2.IMREAD_UNCHANGED))
        for m in bag.messages[topic]
    ]
    assert len(recorded_ids) == 10 and None not in recorded_ids
    svc = start_service("--camera", f"v=bag:path={tmp_path / 'j'},loop=false,speed=0.2")  # its only image topic
    with svc.client(timeout=5) as client:
        status = wait_until(
            lambda: "end of bag" in (s := client.status()["cameras"]["v"])["note"] and s,
            timeout=30,
            what="the end of the bag",
        )
        frames = client.sequence("consecutive", camera="v", count=status["frames_stored"])
    assert status["frames_stored"] + status["frames_dropped"] == 10 and frames
    assert all(f.image.shape == (120, 160, 3) and f.image.dtype.name == "uint8" for f in frames)
    # decoded, each image is a frame the bag recorded, in the recorded order (the worker may drop
    # late frames on a loaded machine, counted as dropped: with none dropped, every one)
    played = [read_stamp(f.image) for f in frames]
    assert len(played) == status["frames_stored"]
    assert set(played) <= set(recorded_ids) and played == sorted(set(played)), (played, recorded_ids)


def options(raw):
    return raw  # the camera checks and completes them itself (fxis_shm.service.camerakinds)


def test_bad_options_name_the_key_and_what_the_bag_holds(recorded, tmp_path):
    path, _ = recorded
    with pytest.raises(ValueError, match="key 'path' is required"):
        BagCamera("v", options({}), 0)
    with pytest.raises(ValueError, match="key 'path': no bag at"):
        BagCamera("v", options({"path": str(tmp_path / "none")}), 0)
    with pytest.raises(ValueError, match="holds no .mcap file"):
        BagCamera("v", options({"path": str(tmp_path)}), 0)
    with pytest.raises(
        ValueError, match=r"no topic '/cam0/image_raw'.*image topics: /left/image_raw, /right/image_raw"
    ):
        BagCamera("v", options({"path": path, "topic": "/cam0/image_raw"}), 0)
    with pytest.raises(ValueError, match="key 'topic' is required: .* has 2 image topics"):
        BagCamera("v", options({"path": path}), 0)


def test_a_bad_bag_camera_stops_start_up_with_the_reason(recorded):
    path, _ = recorded
    result = fxis_run_alone("--camera", f"v=bag:path={path},topic=/nope")
    assert result.returncode == 2  # a setting to change (docs/cli.md)
    assert "camera 'v'" in result.stderr and "/left/image_raw" in result.stderr
    result = fxis("run", "--camera", "v=bag:path=x,speed=0")
    assert result.returncode == 2 and "'speed'" in result.stderr


@pytest.fixture(scope="module")
def video_bags(tmp_path_factory):
    """A recording in h264 (20 frames a camera) and a one-second h264 snapshot of the same cell,
    each with the stamps and ids its /NAME/video/frames topics give."""
    tmp = tmp_path_factory.mktemp("video")
    # rings of 10 s: the snapshot copies its 0.8 s out of them, and a test process held up for
    # a while (a loaded machine) finds a ring of the default 20 slots (1 s) come round past them
    cameras = [arg for camera in CAMERAS for arg in ("--camera", camera)]
    svc = ServiceProcess([*cameras, "--history", "10"], stderr=open(tmp / "service.log", "w")).start()
    try:
        record(svc, tmp / "rec", "--frames", "20", "--codec", "h264", "--gop", "0.3")
        with Client(svc.endpoint) as client:
            client.snapshot(before=0.8, after=0.0, out=str(tmp / "snap"), video=VideoSettings("h264"), cameras=["left"])
    finally:
        stop(svc)
    return {name: (str(tmp / name), read_bag(tmp / name)) for name in ("rec", "snap")}


def recorded_ids(bag, cam) -> dict[int, int]:
    """Recorded capture stamp -> frame id, from /NAME/video/frames."""
    return {rosmsgs.stamp_ns(m.msg.header.stamp): m.msg.frame_id for m in bag.messages[f"/{cam}/video/frames"]}


def test_a_video_bag_replays_its_frames_decoded_with_their_ids_at_the_recorded_spacing(start_service, video_bags):
    path, bag = video_bags["rec"]
    ids = {cam: recorded_ids(bag, cam) for cam in ("left", "right")}
    stamp_of = {cam: {i: t for t, i in ids[cam].items()} for cam in ids}
    cameras = [
        "--camera",
        f"left=bag:path={path},topic=/left/video",
        "--camera",
        f"right=bag:path={path},topic=/right/video",
    ]
    svc = start_service(*cameras, "--slots", "64")
    with svc.client(timeout=5) as client:
        tuples = paired_tuples(client, 10)
    for t in tuples:
        assert t["left"].image.shape == (120, 160) and t["right"].image.shape == (120, 160, 3)  # mono8, bgr8 again
        shown = {cam: read_stamp(f.image) for cam, f in t.items()}
        assert shown["left"] in stamp_of["left"] and shown["left"] == shown["right"]  # each a recorded frame
    recorded = [stamp_of["left"][read_stamp(t["left"].image)] for t in tuples]
    assert_recorded_spacing(tuples, recorded, stamp_of["left"].values())


def test_a_video_snapshot_replays_with_its_recorded_stamps_and_ids(start_service, video_bags):
    path, bag = video_bags["snap"]
    ids = recorded_ids(bag, "left")
    svc = start_service("--camera", f"v=bag:path={path},stamps=recorded,loop=false,speed=0.4", "--slots", "64")
    with svc.client(timeout=5) as client:
        status = wait_until(
            lambda: "end of bag" in (s := client.status()["cameras"]["v"])["note"] and s,
            timeout=30,
            what="the end of the bag",
        )
        frames = client.sequence("range", camera="v", start=min(ids), end=max(ids))  # by the recorded times
    assert status["frames_stored"] + status["frames_dropped"] == len(ids)
    assert len(frames) == status["frames_stored"] > 0
    for f in frames:  # each frame at its recorded stamp, its pixels the frame /v/video/frames names
        assert ids[f.t_capture] == read_stamp(f.image)


def test_a_video_camera_joining_part_way_decodes_from_the_keyframe_before(video_bags):
    """A camera that opens (or restarts) mid-playback starts with a frame that is not a
    keyframe: it plays right only if the decoder began at the keyframe before it."""
    path, bag = video_bags["rec"]
    frames = [(m.log_time, m.msg) for m in bag.messages["/left/video/frames"]]
    k = next(i for i, (_, f) in enumerate(frames) if f.keyframe and i > 0)  # the second keyframe
    join_log, join = frames[k + 1]  # the frame after it: decodes only from that keyframe
    assert not join.keyframe
    # in virtual time: how long opening and decoding take on a loaded machine moves nothing
    clock = VirtualClock()
    # the playback's origin put so that the camera joins 25 ms (half a frame) before that frame is due
    origin = clock.now_ns() - LEAD_NS - (join_log - frames[0][0]) + 25_000_000
    options = {"path": path, "topic": "/left/video", "loop": False, "stamps": "recorded"}
    camera = BagCamera("v", options, origin, clock=clock)
    camera.open()
    try:
        played = []
        while (capture := camera.grab(timeout=1.0)) is not None:
            played.append((capture.t_capture, read_stamp(capture.image)))
    finally:
        camera.close()
    ids = recorded_ids(bag, "left")
    assert played and played[0] == (rosmsgs.stamp_ns(join.header.stamp), join.frame_id), played[:3]
    assert all(ids[t] == shown for t, shown in played)  # every frame after it decodes as the one it is
    assert len(played) + camera.frames_dropped == len(frames) - (k + 1)


@pytest.mark.parametrize("codec, encoder", [("h264", "libx264"), ("h265", "libx265"), ("av1", "libsvtav1")])
def test_the_video_decoder_tells_mono_from_colour_and_keeps_the_stamps_in_each_codec(codec, encoder):
    """What the bag camera plays of a track of each codec: mono8 frames back as mono8, bgr8 as
    bgr8 (by the first picture's chroma), each frame the one it was."""
    for shape, pixels in (((120, 160), MONO), ((120, 160, 3), COLOUR)):
        stream = StreamEncoder("c", Choice(codec, encoder, False), DEFAULT_CRF[codec], None, 2.0, 20.0)
        packets = []
        for i in range(3):
            image = np.random.default_rng(i).integers(0, 256, shape, dtype=np.uint8)  # noise: no easy chroma
            write_stamp(image, 7 + i)
            packets += stream.encode(image, i * 50_000_000, 7 + i, 0)
        packets += stream.finish()
        assert pixels_of(TrackDecoder(codec).picture(packets[0].data)) == pixels
        decoder = TrackDecoder(codec, pixels)
        images = [decoder.decode(p.data) for p in packets]
        assert [(i.shape, read_stamp(i)) for i in images] == [(shape, 7), (shape, 8), (shape, 9)]
