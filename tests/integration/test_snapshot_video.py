"""Snapshots as video (``client.snapshot(video=VideoSettings(...))``, ``fxis snapshot --codec``): the window's
frames from the rings' history encoded with its first frame as a keyframe, read back with
rosbags and decoded with PyAV, every frame's id and capture time checked against the rings."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

from fxis_shm import Client, InvalidArgument, read_stamp
from fxis_shm.errors import ConfigError
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.videotracks import VideoSettings

from ..conftest import fxis, wait_until
from .bags import read_bag
from .conftest import module_service_with_full_rings
from .test_record_video import decoded, nal_types, stamp_ns

pytestmark = pytest.mark.integration
PIXELS = {"a": "gray", "b": "bgr24"}


@pytest.fixture(scope="module")
def history3():
    """Two 160x120 cameras (mono8, bgr8) with three seconds of history, their rings full."""
    args = ["--camera", "a=synthetic:fps=25,width=160,height=120"]
    args += ["--camera", "b=synthetic:fps=20,phase_ms=7,width=160,height=120,pixel_format=bgr8"]
    yield from module_service_with_full_rings([*args, "--history", "3"])


def check_video(bag, cameras=PIXELS) -> None:
    """Each camera's track: one message per frame beside its id, the first a keyframe with its
    parameter sets, every one decoding at once into the frame its id names."""
    for cam in cameras:
        video, frames = bag.messages[f"/{cam}/video"], bag.messages[f"/{cam}/video/frames"]
        assert len(video) == len(frames) > 0
        assert [stamp_ns(m.msg) for m in video] == [rosmsgs.stamp_ns(f.msg.header.stamp) for f in frames]
        assert frames[0].msg.keyframe and nal_types(bytes(video[0].msg.data))[:2] == [7, 8]
        read = [read_stamp(image) for _, image in decoded(video, PIXELS[cam])]
        assert read == [f.msg.frame_id for f in frames]


def test_a_window_from_history_is_video_that_starts_with_a_keyframe_at_its_first_frame(history3, tmp_path):
    with Client(history3.endpoint) as client:
        t = client.clock() - 1_000_000_000  # an event a second ago: its past is in the rings
        result = client.snapshot(at=t, before=1.0, after=0.5, out=str(tmp_path / "v"), video=VideoSettings("h264"))
        rings = client.frame_times(list(PIXELS))
        to_caller = client.clock_estimate().to_caller
    bag = read_bag(tmp_path / "v")
    assert bag.custom_data["encoding"] == "h264" and bag.custom_data["ended"] == "complete"
    assert set(bag.topics) == {f"/{c}/video{s}" for c in PIXELS for s in ("", "/frames")}
    check_video(bag)
    for cam in PIXELS:
        video, frames = bag.messages[f"/{cam}/video"], bag.messages[f"/{cam}/video/frames"]
        assert len(video) == result["cameras"][cam]["frames"]
        # every frame of the window the ring held, the first of them a keyframe, each stamped
        # (and logged, a fixed offset to the wall clock apart) at its capture time
        captured = {row[0]: to_caller(row[1]) for row in rings["cameras"][cam]["frames"]}
        window = [i for i, tc in captured.items() if t - 1e9 <= tc <= t + 0.5e9]
        ids = [f.msg.frame_id for f in frames]
        assert ids == sorted(window), (ids, window)
        assert [stamp_ns(m.msg) for m in video] == [captured[i] for i in ids]
        assert len({m.log_time - stamp_ns(m.msg) for m in video}) == 1
        assert [f.msg.keyframe for f in frames].count(True) == 1  # 1.5 s: within one 2 s GOP


def test_fxis_snapshot_codec_writes_a_video_bag(history3, tmp_path):
    out = tmp_path / "cli"
    command = ("snapshot", "--endpoint", history3.endpoint, "--out", str(out), "--before", "0.5", "--after", "0.2")
    result = fxis(*command, "--codec", "h264", "--gop", "0.2", "--cameras", "a")
    assert result.returncode == 0, result.stderr
    assert "a: " in result.stdout and "0 missing" in result.stdout
    bag = read_bag(out)
    assert set(bag.topics) == {"/a/video", "/a/video/frames"}
    check_video(bag, ["a"])
    frames = bag.messages["/a/video/frames"]
    keys = [rosmsgs.stamp_ns(f.msg.header.stamp) for f in frames if f.msg.keyframe]
    assert len(keys) >= 3 and max(b - a for a, b in zip(keys, keys[1:])) <= 0.2e9 + 0.05e9  # --gop 0.2 at 25 fps


def test_ctrl_c_during_a_video_snapshot_keeps_a_valid_bag_that_decodes(history3, tmp_path):
    out = tmp_path / "c"
    command = [sys.executable, "-m", "fxis_shm.cli", "snapshot", "--endpoint", history3.endpoint, "--out", str(out)]
    proc = subprocess.Popen([*command, "--after", "30", "--codec", "h264"], stdout=subprocess.PIPE, text=True)
    try:
        partial = tmp_path / "c.partial"
        wait_until(lambda: any(p.stat().st_size > 20_000 for p in partial.glob("*.mcap")), timeout=30, what="frames")
        proc.send_signal(signal.SIGINT)
        stdout, _ = proc.communicate(timeout=30)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == 130
    bag = read_bag(out)
    assert bag.custom_data["ended"] == "interrupted by SIGINT" and not (tmp_path / "c.partial").exists()
    check_video(bag)
    assert f"a: {len(bag.messages['/a/video'])} frames" in stdout


def test_encoding_h264_is_video_as_codec_h264(history3, tmp_path):
    """``encoding="h264"`` (the issue's spelling) and ``fxis snapshot --encoding h264`` are
    ``video=VideoSettings("h264")``; both given, they must agree."""
    with Client(history3.endpoint) as client:
        client.snapshot(before=0.3, after=0.0, out=str(tmp_path / "api"), cameras=["a"], encoding="h264")
    command = ("snapshot", "--endpoint", history3.endpoint, "--before", "0.3", "--after", "0", "--cameras", "b")
    result = fxis(*command, "--out", str(tmp_path / "cli"), "--encoding", "h264", "--codec", "h264")
    assert result.returncode == 0, result.stderr
    for folder, cam in (("api", "a"), ("cli", "b")):
        bag = read_bag(tmp_path / folder)
        assert bag.custom_data["encoding"] == "h264" and set(bag.topics) == {f"/{cam}/video", f"/{cam}/video/frames"}
        check_video(bag, [cam])
    result = fxis(*command, "--out", str(tmp_path / "no"), "--encoding", "h265", "--codec", "h264")
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [
        "fxis snapshot: --encoding h265 and --codec h264 disagree: give one of them (both name the video codec)"
    ]
    assert not (tmp_path / "no").exists()


@pytest.mark.parametrize(
    "kwargs, error",
    [
        ({"video": VideoSettings("vp8")}, (ConfigError, "--codec vp8: unknown")),
        (
            {"video": VideoSettings("h264"), "encoding": "jpeg"},
            (InvalidArgument, "codec h264 writes video: it takes no encoding"),
        ),
        ({"video": VideoSettings("h264", crf=60)}, (ConfigError, "--crf 60: out of range")),
        ({"encoding": "h264", "video": VideoSettings("av1")}, (ConfigError, "encoding h264 and codec av1 disagree")),
    ],
)
def test_bad_video_settings_are_refused_before_anything_is_made(history3, tmp_path, kwargs, error):
    kind, words = error
    with Client(history3.endpoint) as client:
        with pytest.raises(kind, match=words):
            client.snapshot(before=0.2, after=0.0, out=str(tmp_path / "bad"), **kwargs)
    assert not (tmp_path / "bad").exists() and not (tmp_path / "bad.partial").exists()
    result = fxis("snapshot", "--endpoint", history3.endpoint, "--out", str(tmp_path / "x"), "--codec", "h263")
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not (tmp_path / "x").exists()
