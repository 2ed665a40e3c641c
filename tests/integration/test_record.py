"""``fxis record`` against a real service; the bag read back with rosbags (an independent reader)."""

import os

import cv2
import numpy as np
import pytest

from fxis_shm import read_stamp
from fxis_shm.formats import rosmsgs

from ..conftest import fxis
from .bags import FPS, read_bag, record, record_until_ctrl_c, two_cameras

pytestmark = pytest.mark.integration
cell = pytest.fixture(scope="module", name="cell")(two_cameras)
SECONDS = 2.0


@pytest.fixture(scope="module")
def raw_bag(cell, tmp_path_factory):
    out = tmp_path_factory.mktemp("bags") / "raw"
    result = record(cell, out, "--seconds", str(SECONDS))
    return out, result


def test_a_recording_opens_with_rosbags_one_image_topic_per_camera(raw_bag):
    out, result = raw_bag
    bag = read_bag(out)
    assert bag.topics == {"/left/image_raw": rosmsgs.IMAGE, "/right/image_raw": rosmsgs.IMAGE}
    assert bag.custom_data["clock"] == "CLOCK_MONOTONIC"
    for cam, encoding, shape in (("left", "mono8", (120, 160)), ("right", "bgr8", (120, 160, 3))):
        messages = bag.messages[f"/{cam}/image_raw"]
        stamps = [m.stamp for m in messages]
        assert all(b > a for a, b in zip(stamps, stamps[1:]))
        assert SECONDS * 1e9 / 2 < stamps[-1] - stamps[0] < SECONDS * 1e9  # the frames of the 2 s asked
        for m in messages:
            assert (m.msg.encoding, m.msg.height, m.msg.width, m.msg.header.frame_id) == (encoding, *shape[:2], cam)
            assert m.msg.step == shape[1] * (3 if encoding == "bgr8" else 1)
            assert rosmsgs.image_array(m.msg).shape == shape
        # each frame once, in order: the pixel stamps (the frame counter) go up; a frame not
        # recorded is reported (test_the_summary_counts_frames_and_missed; how many a loaded
        # machine loses: bench/costs/observers.py prints the recorder's report)
        ids = [read_stamp(rosmsgs.image_array(m.msg)) for m in messages]
        assert all(b > a for a, b in zip(ids, ids[1:])), ids
        # log times are wall-clock: the stamp plus one offset, written in the metadata
        offset = int(bag.custom_data["clock_to_realtime_ns"])
        assert all(m.log_time == m.stamp + offset for m in messages)
    assert "missed" in result.stdout and "left" in result.stdout


def test_the_summary_counts_frames_and_missed(raw_bag):
    out, result = raw_bag
    rows = {line.split()[0]: line.split() for line in result.stdout.splitlines()[1:3]}
    bag = read_bag(out)
    for cam in ("left", "right"):
        messages = bag.messages[f"/{cam}/image_raw"]
        assert rows[cam][2] == str(len(messages))
        # every frame id absent from the bag is reported: missed by the recorder, or dropped by the camera
        ids = [read_stamp(rosmsgs.image_array(m.msg)) for m in messages]
        absent = ids[-1] - ids[0] + 1 - len(ids)
        missed, dropped = int(rows[cam][3]), int(rows[cam][4])
        assert 0 <= absent <= missed + dropped, (absent, rows[cam])
    assert "recording left, right" in result.stderr  # one line per stage: not a terminal


def test_tuples_share_a_step_stamp_and_regroup_from_the_side_topic(cell, tmp_path):
    record(cell, tmp_path / "t", "--tuples", "--frames", "12", "--rate", "10")
    bag = read_bag(tmp_path / "t")
    assert bag.topics[rosmsgs.TUPLES_TOPIC] == rosmsgs.TUPLE
    tuples = bag.messages[rosmsgs.TUPLES_TOPIC]
    assert len(tuples) == 12
    steps = [t.stamp for t in tuples]
    assert all(abs((b - a) - 100_000_000) <= 1 for a, b in zip(steps, steps[1:]))  # --rate 10
    by_stamp = {cam: {m.stamp: m.msg for m in bag.messages[f"/{cam}/image_raw"]} for cam in ("left", "right")}
    for t in tuples:
        assert list(t.msg.cameras) == ["left", "right"]
        for cam, frame_id, capture in zip(t.msg.cameras, t.msg.frame_ids, t.msg.capture_stamps):
            image = rosmsgs.image_array(by_stamp[cam][t.stamp])  # the image carries the step's stamp
            assert read_stamp(image) == frame_id
            assert abs(rosmsgs.stamp_ns(capture) - t.stamp) <= 1e9 / FPS  # its frame is near the step
        assert len(set(int(i) for i in t.msg.frame_ids)) == 1  # the two cameras capture together


def test_jpeg_images_are_compressed_images_of_the_frames_they_name(cell, tmp_path):
    """JPEG changes the stamp's bytes; its 8x8 blocks survive (fxis_shm.formats.stamp), so each
    decoded image still reads as the frame /fxis/tuples names."""
    record(cell, tmp_path / "j", "--tuples", "--frames", "5", "--encoding", "jpeg", "--quality", "90")
    bag = read_bag(tmp_path / "j")
    assert bag.topics["/left/image_raw/compressed"] == rosmsgs.COMPRESSED
    left = {m.stamp: m.msg for m in bag.messages["/left/image_raw/compressed"]}
    assert len(bag.messages[rosmsgs.TUPLES_TOPIC]) == 5
    for t in bag.messages[rosmsgs.TUPLES_TOPIC]:
        msg = left[t.stamp]
        assert msg.format == "jpeg"  # the name Foxglove shows
        image = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_UNCHANGED)
        assert image.shape == (120, 160)
        assert read_stamp(image) == int(t.msg.frame_ids[0])


def test_ctrl_c_ends_the_recording_with_a_valid_bag(cell, tmp_path):
    out = tmp_path / "c"
    returncode, stdout, stderr = record_until_ctrl_c(cell, out, 200_000)
    assert returncode == 130, stderr  # stopped by a signal, what was recorded kept
    assert "interrupted by SIGINT" in stderr
    bag = read_bag(out)
    assert len(bag.messages["/left/image_raw"]) > 0
    assert f"{len(bag.messages['/left/image_raw'])}" in stdout
    assert bag.custom_data["ended"] == "interrupted by SIGINT"


@pytest.mark.parametrize(
    "args, words",
    [
        (["--seconds", "-1"], ["--seconds", "> 0"]),
        (["--frames", "0"], ["--frames"]),
        (["--quality", "50"], ["--quality", "jpeg"]),
        (["--encoding", "jpeg", "--quality", "101"], ["--quality", "at most 100"]),
        (["--cameras", "left,centre"], ["--cameras", "centre", "left, right"]),
        (["--seconds", "1", "--frames", "3"], ["not allowed with"]),
        (["--encoding", "png"], ["--encoding", "invalid choice"]),
    ],
)
def test_bad_input_exits_2_naming_the_setting(cell, tmp_path, args, words):
    result = fxis("record", "--endpoint", cell.endpoint, "--out", str(tmp_path / "x"), *args)
    assert result.returncode == 2
    assert all(w in result.stderr for w in words), result.stderr
    assert not (tmp_path / "x").exists()


def test_an_existing_bag_is_never_overwritten(cell, tmp_path):
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "metadata.yaml").write_text("keep me")
    result = fxis("record", "--endpoint", cell.endpoint, "--out", str(tmp_path / "old"), "--frames", "1")
    assert result.returncode == 2 and "--out" in result.stderr and "not an empty folder" in result.stderr
    assert (tmp_path / "old" / "metadata.yaml").read_text() == "keep me"


def test_the_mcap_file_names_its_clock_in_a_metadata_record(raw_bag):
    from mcap.reader import make_reader

    out, _ = raw_bag
    with open(os.path.join(out, "raw_0.mcap"), "rb") as f:
        records = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    assert records["fxis"]["clock"] == "CLOCK_MONOTONIC"
    assert records["fxis"]["mode"] == "frames" and int(records["fxis"]["clock_to_realtime_ns"]) > 0
    assert records["fxis"]["ended"] == "complete"  # written once, complete, when the bag was closed
    assert records["fxis.begun"]["clock"] == "CLOCK_MONOTONIC"  # what a killed recording still says


def test_a_recorder_that_cannot_keep_up_says_how_many_frames_it_missed(start_service, tmp_path):
    """A camera at 1000 fps into a ring of 2 slots comes round faster than any poll: the
    recorder loses frames, and counts every one of them."""
    svc = start_service("--camera", "fast=synthetic:fps=1000,width=64,height=48", "--slots", "2")
    result = record(svc, tmp_path / "m", "--seconds", "1")
    frames, missed, dropped = (int(v) for v in result.stdout.splitlines()[1].split()[2:5])
    ids = [read_stamp(rosmsgs.image_array(m.msg)) for m in read_bag(tmp_path / "m").messages["/fast/image_raw"]]
    assert len(ids) == frames and missed > 0
    span = ids[-1] - ids[0] + 1
    assert span - frames - missed <= dropped  # every gap not counted as missed, the camera dropped
    assert frames + missed <= 1000 * 1 + 1  # nothing counted twice: the camera made 1000 frames in 1 s


def test_frames_a_camera_restart_cost_are_counted_and_the_exit_code_says_so(start_service, tmp_path):
    """Issue 42, finding 7: camera a's worker killed mid-recording. The recording goes on and
    says, per camera, what the restart cost (by ids and capture times), in the summary, the
    metadata's ``ended`` and the bag's ``fxis`` record, and exits 1 (done, something missing)."""
    import json
    import signal
    import subprocess
    import sys

    from ..conftest import wait_until

    svc = start_service("--camera", f"a=synthetic:fps={FPS},width=160,height=120", "--camera", "b=synthetic:fps=10")
    out = tmp_path / "restarted"
    command = [sys.executable, "-m", "fxis_shm.cli", "record", "--endpoint", svc.endpoint, "--out", str(out)]
    proc = subprocess.Popen([*command, "--seconds", "6"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        with svc.client() as client:
            generation = client.status()["cameras"]["a"]["generation"]
            wait_until(lambda: (out / "restarted_0.mcap").exists(), timeout=20, what="the recording to begin")
            # the recording's window holds frames of this generation (captured after the bag was
            # made, so after the recording began): the restart then lies inside the recording,
            # whether or not the recorder has polled them before the kill (it takes them after)
            first = client.image("a").frame_id
            wait_until(
                lambda: client.image("a").frame_id >= first + 3,
                timeout=20,
                what="3 frames of a captured in the recording",
            )
            os.kill(svc.children()["camera:a"], signal.SIGKILL)
            wait_until(
                lambda: client.status()["cameras"]["a"].get("generation", generation) > generation,
                timeout=20,
                what="camera a back in a new generation",
            )
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 1, stderr
    assert "done, but frames are missing where cameras restarted" in stderr
    said = [line for line in stdout.splitlines() if line.startswith("a: restarted, generation")]
    assert len(said) == 1 and not any(line.startswith("b: restarted") for line in stdout.splitlines()), stdout
    bag = read_bag(out)
    assert bag.custom_data["ended"].startswith("done, but frames missing where cameras restarted: a ")
    (gap,) = json.loads(bag.custom_data["restarts"])["a"]
    assert gap["generations"][1] > gap["generations"][0] and gap["missing"] > 0
    # the bag agrees: the capture times either side of the hole, over the camera's period
    stamps = [m.stamp for m in bag.messages["/a/image_raw"]]
    hole = gap["first"][1] - gap["last"][1]
    assert hole in [b - a for a, b in zip(stamps, stamps[1:])]  # two frames recorded side by side
    assert gap["missing"] == round(hole * FPS / 1e9) - 1
    assert f"{gap['missing']} frames missing" in said[0]
