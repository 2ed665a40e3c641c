"""``fxis export BAG --rerun OUT.rrd`` and ``fxis view --rerun`` against a real service of
synthetic cameras: the .rrd files read back with rerun-sdk's own reader (tests/integration/rrdread.py),
checked against the bag read with rosbags and against the pixels' own frame-id stamps."""

import os
import subprocess
import sys
import time

import numpy as np
import pytest

from fxis_shm import read_stamp
from fxis_shm.formats import rosmsgs

from ..conftest import fxis
from .bags import read_bag, record, two_cameras
from .conftest import SMALL
from .rrdread import image_of, read_rrd

pytestmark = pytest.mark.integration
cell = pytest.fixture(scope="module", name="cell")(two_cameras)
CAMERAS = ("left", "right")
THRESHOLD_MS = 3.0  # fxis_shm.core.syncstats.DEFAULT_THRESHOLD_MS, the verdict's default


def export(bag, out):
    result = fxis("export", str(bag), "--rerun", str(out))
    assert result.returncode == 0, result.stderr
    return result.stdout


def one_line_error(result, *words):
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for word in words:
        assert word in lines[0], lines[0]


@pytest.mark.parametrize(("codec", "seconds"), [("h264", 2.0), ("h265", 1.0), ("av1", 1.0)])
def test_a_video_bag_becomes_video_streams_of_the_same_packets_at_their_capture_times(cell, tmp_path, codec, seconds):
    import rerun as rr
    from rerun.experimental.video import detect_gop_start

    record(cell, tmp_path / "bag", "--seconds", str(seconds), "--codec", codec, "--gop", "0.5")
    said = export(tmp_path / "bag", tmp_path / "video.rrd")
    bag, rrd = read_bag(tmp_path / "bag"), read_rrd(tmp_path / "video.rrd")
    assert set(rrd.entities) == {f"/cameras/{c}" for c in CAMERAS}  # no tuples in a bag of frames
    rerun_codec = rr.VideoCodec[codec.upper()]
    for cam in CAMERAS:
        video = bag.messages[rosmsgs.video_topic(cam)]
        frames = bag.messages[rosmsgs.video_frames_topic(cam)]
        rows = rrd.entities[f"/cameras/{cam}"]
        assert f"{cam} {len(video)} video packets" in said
        assert rrd.static[f"/cameras/{cam}"]["VideoStream:codec"] == rerun_codec.value
        assert len(rows) == len(video) > 15 * seconds
        assert [r.capture_ns for r in rows] == [rosmsgs.stamp_ns(m.msg.timestamp) for m in video]
        samples = [bytes(r.cells["VideoStream:sample"]) for r in rows]
        assert samples == [bytes(m.msg.data) for m in video]  # not re-encoded
        assert [r.frame_id for r in rows] == [f.msg.frame_id for f in frames]
        keyframes = [f.msg.keyframe for f in frames]
        assert [r.cells["VideoStream:is_keyframe"] for r in rows] == keyframes
        assert [detect_gop_start(s, rerun_codec) for s in samples] == keyframes  # Rerun's own parser agrees
        assert keyframes[0] and sum(keyframes) >= 2


def test_a_bag_of_jpeg_tuples_puts_each_frame_at_its_capture_time_and_logs_each_tuples_skew(cell, tmp_path):
    record(cell, tmp_path / "bag", "--seconds", "2", "--encoding", "jpeg", "--tuples")
    said = export(tmp_path / "bag", tmp_path / "tuples.rrd")
    bag, rrd = read_bag(tmp_path / "bag"), read_rrd(tmp_path / "tuples.rrd")
    tuples = bag.messages[rosmsgs.TUPLES_TOPIC]
    assert set(rrd.entities) == {"/cameras/left", "/cameras/right", "/sync/skew_ms", "/sync/synced"}
    assert f"{len(tuples)} tuples' skew and sync verdict" in said
    for cam in CAMERAS:
        images = bag.messages[rosmsgs.image_topic(cam, compressed=True)]
        of_tuples = [
            (
                rosmsgs.stamp_ns(t.msg.capture_stamps[t.msg.cameras.index(cam)]),
                t.msg.frame_ids[t.msg.cameras.index(cam)],
            )
            for t in tuples
        ]
        rows = rrd.entities[f"/cameras/{cam}"]
        assert len(rows) == len(images) == len(tuples) > 20
        assert [(r.capture_ns, r.frame_id) for r in rows] == of_tuples  # the capture time, not the step's
        assert [bytes(r.cells["EncodedImage:blob"]) for r in rows] == [bytes(m.msg.data) for m in images]
        assert {r.cells["EncodedImage:media_type"] for r in rows} == {"image/jpeg"}
    skews = [
        (max(map(rosmsgs.stamp_ns, t.msg.capture_stamps)) - min(map(rosmsgs.stamp_ns, t.msg.capture_stamps))) / 1e6
        for t in tuples
    ]
    steps = [rosmsgs.stamp_ns(t.msg.header.stamp) for t in tuples]
    assert [r.capture_ns for r in rrd.entities["/sync/skew_ms"]] == steps
    assert rrd.cells("/sync/skew_ms", "Scalars:scalars") == pytest.approx(skews, abs=1e-9)
    assert rrd.cells("/sync/synced", "Scalars:scalars") == [float(s <= THRESHOLD_MS) for s in skews]


def test_a_raw_bag_becomes_images_of_the_same_pixels(cell, tmp_path):
    record(cell, tmp_path / "bag", "--frames", "10")
    export(tmp_path / "bag", tmp_path / "raw.rrd")
    bag, rrd = read_bag(tmp_path / "bag"), read_rrd(tmp_path / "raw.rrd")
    for cam in CAMERAS:
        images = bag.messages[rosmsgs.image_topic(cam)]
        rows = rrd.entities[f"/cameras/{cam}"]
        assert len(rows) == len(images) == 10
        assert [r.capture_ns for r in rows] == [m.stamp for m in images]
        assert all(r.frame_id is None for r in rows)  # a bag of frames names no ids beside raw images
        for row, message in zip(rows, images):
            assert np.array_equal(image_of(row), rosmsgs.image_array(message.msg))


def view_into_file(out, endpoints: list[str], ticks: int):
    """``fxis view ENDPOINTS --rerun --rerun-save OUT`` for ``ticks`` tuples at 10 Hz, read back:
    (its stdout, the recording, the CLOCK_MONOTONIC span it ran in)."""
    start = time.monotonic_ns()
    result = fxis("view", *endpoints, "--rerun", "--rerun-save", str(out), "--tuples", str(ticks), "--rate", "10")
    end = time.monotonic_ns()
    assert result.returncode == 0, result.stderr
    return result.stdout, read_rrd(out), (start, end)


def assert_frames_and_tuples(said: str, rrd, cameras, ticks: int, span: tuple[int, int]) -> None:
    """Each camera's frames once each, in order, at capture times of this host's CLOCK_MONOTONIC,
    their pixels the frame the frame_id timeline names; a skew and a verdict for every tick, each
    skew that of logged frames."""
    assert set(rrd.entities) == {*(f"/cameras/{c}" for c in cameras), "/sync/skew_ms", "/sync/synced"}
    assert len(rrd.entities["/sync/skew_ms"]) == len(rrd.entities["/sync/synced"]) == ticks  # every tick answered
    assert f"fxis view: {ticks} tuples" in said
    for cam in cameras:
        rows = rrd.entities[f"/cameras/{cam}"]
        assert f"{cam} {len(rows)}" in said.splitlines()[-1]
        assert 1 <= len(rows) <= ticks
        ids = [r.frame_id for r in rows]
        assert ids == sorted(set(ids))  # each frame once, in order
        assert all(span[0] - 5e9 < r.capture_ns < span[1] for r in rows)
        assert [read_stamp(image_of(r)) for r in rows] == ids  # the pixels are the frame the timeline names
    skews = rrd.cells("/sync/skew_ms", "Scalars:scalars")
    times = [[r.capture_ns for r in rrd.entities[f"/cameras/{cam}"]] for cam in cameras[:2]]
    logged = {round(abs(a - b) / 1e6, 6) for a in times[0] for b in times[1]}
    assert {round(s, 6) for s in skews} <= logged  # each tuple's frames were logged: its skew is theirs
    assert rrd.cells("/sync/synced", "Scalars:scalars") == [float(s <= THRESHOLD_MS) for s in skews]


def test_view_saves_the_running_services_tuples_each_frame_at_its_capture_time(cell, tmp_path):
    said, rrd, span = view_into_file(tmp_path / "live.rrd", [cell.endpoint], ticks=15)
    assert_frames_and_tuples(said, rrd, CAMERAS, 15, span)


def test_view_of_a_cell_of_two_services_logs_both_in_one_recording(start_service, tmp_path):
    a = start_service("--camera", f"a=synthetic:fps=20,{SMALL}")
    b = start_service("--camera", f"b=synthetic:fps=20,phase_ms=20,{SMALL}")
    said, rrd, span = view_into_file(tmp_path / "cell.rrd", [a.endpoint, b.endpoint], ticks=10)
    assert said.startswith(f"fxis view: a, b of {a.endpoint}, {b.endpoint} at 10 Hz into ")
    assert_frames_and_tuples(said, rrd, ("a", "b"), 10, span)


def test_bad_inputs_exit_2_in_one_line(cell, tmp_path):
    """Those that need a bag or a service (the others: test_cli_errors.py's table)."""
    taken = tmp_path / "taken.rrd"
    taken.write_bytes(b"")
    record(cell, tmp_path / "bag", "--frames", "2")
    one_line_error(fxis("export", str(tmp_path / "bag"), "--rerun", str(taken)), "--rerun", "exists")
    one_line_error(fxis("export", str(tmp_path / "bag"), "--rerun", str(tmp_path / "no" / "a.rrd")), "does not exist")
    one_line_error(
        fxis("export", str(tmp_path / "bag"), "--rerun", str(tmp_path / "b.rrd"), "--camera", "left"),
        "without --camera",
    )
    one_line_error(fxis("export", str(tmp_path / "bag")), "--rerun OUT.rrd")
    one_line_error(fxis("view", cell.endpoint, "--rerun", "--rerun-save", str(taken)), "--rerun-save", "exists")
    one_line_error(
        fxis("view", cell.endpoint, "--rerun", "--cameras", "nosuch", "--rerun-save", str(tmp_path / "d.rrd")), "nosuch"
    )
    assert not any((tmp_path / n).exists() for n in ("a.rrd", "b.rrd", "c.rrd", "d.rrd"))
    assert taken.read_bytes() == b""


def test_without_rerun_sdk_fxis_works_and_says_how_to_install_it(cell, tmp_path):
    """A Python where ``import rerun`` fails, as where the extra is not installed."""
    absent = tmp_path / "absent"
    (absent / "rerun").mkdir(parents=True)
    (absent / "rerun" / "__init__.py").write_text("raise ImportError(\"No module named 'rerun'\")\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(absent), *sys.path])}

    def run(*args):
        command = [sys.executable, "-m", "fxis_shm.cli", *args]
        return subprocess.run(command, capture_output=True, text=True, timeout=60, env=env)

    record(cell, tmp_path / "bag", "--frames", "2")
    assert run("status", "--endpoint", cell.endpoint).returncode == 0
    one_line_error(run("export", str(tmp_path / "bag"), "--rerun", str(tmp_path / "a.rrd")), "extra 'rerun'", "pip")
    one_line_error(run("view", cell.endpoint, "--rerun", "--rerun-save", str(tmp_path / "b.rrd")), "extra 'rerun'")
    assert not (tmp_path / "a.rrd").exists() and not (tmp_path / "b.rrd").exists()


def test_a_viewer_that_is_not_there_ends_the_view_in_a_line_not_a_hang(cell):
    from fxis_shm.service.launch import free_tcp_port

    url = f"rerun+http://127.0.0.1:{free_tcp_port()}/proxy"
    result = fxis("view", cell.endpoint, "--rerun", "--rerun-connect", url, "--tuples", "3", timeout=60)
    assert result.returncode == 4, (result.stdout, result.stderr)  # FAILED: the data went nowhere
    last = result.stderr.strip().splitlines()[-1]  # above it: rerun-sdk's own warnings of the connection
    assert last.startswith("fxis view: Rerun did not take what was logged") and url in last, result.stderr
