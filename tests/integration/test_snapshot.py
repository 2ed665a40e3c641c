"""Snapshots: every frame captured in [t - before, t + after], the past from the rings and the
future as it comes, into a bag that rosbags reads; nothing missing without saying so."""

from __future__ import annotations

import _thread
import json
import os
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest

from fxis_shm import Client, InvalidArgument
from fxis_shm.client.snapshot import Interrupted
from fxis_shm.errors import DiskFull
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.stamp import read_stamp

from ..conftest import fxis, run_in_threads, wait_until
from .bags import read_bag
from .conftest import SMALL, module_service_with_full_rings

pytestmark = pytest.mark.integration

CAMERAS = ("a", "b")


@pytest.fixture(scope="module")
def history3():
    """A service with three seconds of history per camera, its rings full (as after a while)."""
    args = ["--camera", f"a=synthetic:fps=25,{SMALL}", "--camera", f"b=synthetic:fps=20,phase_ms=7,{SMALL}"]
    yield from module_service_with_full_rings([*args, "--history", "3"])


def images(bag, camera: str) -> list:
    return bag.messages[rosmsgs.image_topic(camera)]


def drops(svc) -> dict[str, int]:
    """How many frames each camera has dropped so far (a loaded machine makes it fall behind)."""
    with Client(svc.endpoint) as client:
        return {c: s["frames_dropped"] for c, s in client.status()["cameras"].items()}


def check_window(bag, t: int, before: float, after: float, dropped: dict[str, int]) -> None:
    """Every frame of the window the camera stored: consecutive pixel stamps but for the ids the
    bag reports missing, no more of them than the camera itself dropped (``dropped``, during
    the snapshot), and stamps inside the window."""
    missing = json.loads(bag.custom_data["missing"])
    for camera in CAMERAS:
        messages = images(bag, camera)
        ids = [read_stamp(rosmsgs.image_array(m.msg)) for m in messages]
        gaps = sorted(set(range(ids[0], ids[-1] + 1)) - set(ids))
        assert gaps == missing[camera], f"{camera}: frames missing from the window that the bag does not name"
        assert len(gaps) <= dropped[camera], f"{camera}: frames missing that the camera stored"
        stamps = [m.stamp for m in messages]
        assert t - before * 1e9 <= stamps[0] and stamps[-1] <= t + after * 1e9
        fps = 25 if camera == "a" else 20
        assert len(ids) + len(gaps) >= (before + after) * fps - 2  # the whole window, not a part of it
    assert int(bag.custom_data["event_ns"]) == t


def dropped_since(svc, before: dict[str, int]) -> dict[str, int]:
    after = drops(svc)
    return {c: after[c] - before[c] for c in CAMERAS}


def test_an_event_that_arrives_late_keeps_the_seconds_around_it(history3, tmp_path):
    dropped = drops(history3)
    with Client(history3.endpoint) as client:
        t = client.clock()
        wait_until(lambda: client.clock() > t + 1_200_000_000, what="the event, 1.2 s late")
        # its window ends before it arrives and starts 1.7 s back in 3 s rings: 1.3 s to spare
        # for a process held up on a busy machine
        result = client.snapshot(at=t, before=0.5, after=1.0, out=str(tmp_path / "event"))
    for name, kept in result["cameras"].items():
        assert kept["complete"] and not kept["gone_before_ms"], (name, kept)
    check_window(read_bag(tmp_path / "event"), t, 0.5, 1.0, dropped_since(history3, dropped))
    assert not (tmp_path / "event.partial").exists()


def test_a_window_into_the_future_while_tuples_are_pulled_and_a_recording_runs(history3, tmp_path):
    stop = threading.Event()

    def pull_tuples():
        with Client(history3.endpoint) as puller:
            while not stop.is_set():
                puller.tuple()

    puller = threading.Thread(target=pull_tuples, daemon=True)
    puller.start()
    dropped = drops(history3)
    record = ["record", "--endpoint", history3.endpoint, "--out", str(tmp_path / "rec"), "--seconds", "3"]
    recording = subprocess.Popen([sys.executable, "-m", "fxis_shm.cli", *record], stderr=subprocess.DEVNULL)
    try:
        with Client(history3.endpoint) as client:
            t = client.clock()
            result = client.snapshot(at=t, before=0.5, after=1.5, out=str(tmp_path / "future"))
        assert all(kept["complete"] for kept in result["cameras"].values())
    finally:
        stop.set()
        puller.join(10)
        recording.wait(30)
    check_window(read_bag(tmp_path / "future"), t, 0.5, 1.5, dropped_since(history3, dropped))


def test_overlapping_snapshots_each_hold_their_own_window(history3, tmp_path):
    dropped = drops(history3)
    with Client(history3.endpoint) as client:
        t = client.clock()
    numbers = iter(range(3))

    def one() -> None:
        i = next(numbers)
        with Client(history3.endpoint) as client:
            client.snapshot(at=t + i * 300_000_000, before=0.6, after=0.6, out=str(tmp_path / f"s{i}"))

    run_in_threads(one, 3, timeout=30)
    dropped = dropped_since(history3, dropped)
    for i in range(3):
        check_window(read_bag(tmp_path / f"s{i}"), t + i * 300_000_000, 0.6, 0.6, dropped)


def test_a_window_older_than_the_history_says_what_was_gone(history3, tmp_path):
    with Client(history3.endpoint) as client:
        wait_until(lambda: client.status()["uptime_s"] > 5.5, what="frames older than the window's start")
        asked = client.clock()
        t = asked - 2_500_000_000  # its start is 4 s ago, its end 1.5 s ago: the rings hold 3
        result = client.snapshot(at=t, before=1.5, after=1.0, out=str(tmp_path / "old"))
        answered = client.clock()
    gone = {name: kept["gone_before_ms"] for name, kept in result["cameras"].items()}
    bag = read_bag(tmp_path / "old")
    assert json.loads(bag.custom_data["gone_before_ms"]) == gone
    start = t - 1_500_000_000
    missing = json.loads(bag.custom_data["missing"])
    for camera, period_ms in (("a", 40), ("b", 50)):
        # about 1 s of the window was older than the ring at the snapshot's first look (less where
        # the camera dropped frames: the ring then spans longer; more by as long as the snapshot
        # took to look, a loaded machine's delay): gone_before_ms
        copied_by_ms = (answered - 3_000_000_000 - start) / 1e6
        assert 500 <= gone[camera] <= copied_by_ms + period_ms, (gone, copied_by_ms, (answered - asked) / 1e6)
        # the frames the ring lost are named missing, by the ids before the first one kept: those
        # gone at the first look, and those the ring overwrote before they were copied
        first_id = read_stamp(rosmsgs.image_array(images(bag, camera)[0].msg))
        lost = [i for i in missing[camera] if i < first_id]
        assert lost == list(range(first_id - len(lost), first_id)), (camera, lost, first_id)
        assert len(lost) >= gone[camera] / period_ms - 1, (camera, len(lost), gone)
        # and the bag lacks what it names: its first frame comes that many periods after the start
        first_ms = (images(bag, camera)[0].stamp - start) / 1e6
        assert abs(first_ms - len(lost) * period_ms) <= period_ms, (camera, first_ms, len(lost))
    assert missing == {c: kept["missing"] for c, kept in result["cameras"].items()}


def test_a_window_wholly_older_than_the_history_writes_no_bag_and_names_every_frame_missing(history3, tmp_path):
    with Client(history3.endpoint) as client:
        wait_until(lambda: client.status()["uptime_s"] > 6, what="cameras older than the window")
        t = client.clock() - 4_200_000_000  # the window is 4.7 .. 3.7 s ago; the rings hold the last 3 s
        result = client.snapshot(at=t, before=0.5, after=0.5, out=str(tmp_path / "gone"))
    assert result["out"] is None and not (tmp_path / "gone").exists() and not (tmp_path / "gone.partial").exists()
    for camera, period_ms in (("a", 40), ("b", 50)):
        kept = result["cameras"][camera]
        assert kept["frames"] == 0 and kept["gone_before_ms"] == 1000.0
        assert abs(len(kept["missing"]) - 1000 / period_ms) <= 1, kept
    at = str(t)
    cli = fxis("snapshot", "--endpoint", history3.endpoint, "--out", str(tmp_path / "gone"), "--at", at, "--after", "0")
    assert cli.returncode == 1, cli.stderr
    assert "no bag written: the rings held no frame of the window" in cli.stdout
    assert not (tmp_path / "gone").exists() and not (tmp_path / "gone.partial").exists()


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"before": -1}, "before must be seconds >= 0"),
        ({"after": float("nan")}, "after must be seconds >= 0"),
        ({"before": 0, "after": 0}, "needs a window"),
        ({"at": "now"}, "at must be a whole number of ns"),
        ({"encoding": "png"}, "encoding must be raw or jpeg"),
    ],
)
def test_bad_windows_get_clear_errors_and_the_service_keeps_serving(history3, tmp_path, kwargs, words):
    with Client(history3.endpoint) as client:
        with pytest.raises(InvalidArgument, match=words):
            client.snapshot(out=str(tmp_path / "bad"), **kwargs)
        assert client.tuple()["a"].frame_id >= 0
    assert not (tmp_path / "bad").exists()


def test_fxis_snapshot_writes_the_bag_and_reports_each_camera(history3, tmp_path):
    result = fxis(
        "snapshot", "--endpoint", history3.endpoint, "--out", str(tmp_path / "cli"), "--before", "0.5", "--after", "0.2"
    )
    assert result.returncode == 0, result.stderr
    assert "a: " in result.stdout and "0 missing" in result.stdout
    bag = read_bag(tmp_path / "cli")
    assert {rosmsgs.image_topic(c) for c in CAMERAS} <= set(bag.topics)
    assert all(isinstance(rosmsgs.image_array(m.msg), np.ndarray) for m in images(bag, "a"))
    assert sorted(os.listdir(tmp_path / "cli")) == ["cli_0.mcap", "metadata.yaml"]  # named as rosbag2 names it
    records = fxis_records(tmp_path / "cli" / "cli_0.mcap")
    assert [name for name, _ in records].count("fxis") == 1
    final = dict(records)["fxis"]
    assert final == bag.custom_data and final["clock"] == "CLOCK_MONOTONIC" and final["ended"] == "complete"
    assert json.loads(final["missing"]).keys() == json.loads(final["gone_before_ms"]).keys() == set(CAMERAS)


def fxis_records(mcap) -> list[tuple[str, dict]]:
    from mcap.reader import make_reader

    with open(mcap, "rb") as f:
        return [(m.name, dict(m.metadata)) for m in make_reader(f).iter_metadata()]


def test_the_bag_names_the_callers_clock(history3, tmp_path):
    with Client(history3.endpoint, clock="realtime") as client:
        client.snapshot(before=0.2, after=0.0, out=str(tmp_path / "rt"))
    assert read_bag(tmp_path / "rt").custom_data["clock"] == "CLOCK_REALTIME"


@pytest.fixture
def python_ctrl_c():
    """Python's own Ctrl-C handler for the test, whatever an earlier test of this worker left (under
    the whole suite the test below never saw a KeyboardInterrupt: a handler that raised none)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_ctrl_c_in_the_library_keeps_the_bag_of_what_was_copied_and_says_where(history3, tmp_path, python_ctrl_c):
    out = tmp_path / "lib"
    ctrl_c = threading.Timer(1.0, _thread.interrupt_main)  # KeyboardInterrupt in this thread, as Ctrl-C
    with Client(history3.endpoint) as client:
        ctrl_c.start()
        try:
            with pytest.raises(Interrupted) as info:
                client.snapshot(before=0.5, after=5.0, out=str(out))
        finally:
            ctrl_c.cancel()
    assert isinstance(info.value, KeyboardInterrupt)  # a caller's `except KeyboardInterrupt` still sees it
    result = info.value.result
    assert result["out"] == str(out) and f"in {out}, a valid bag" in str(info.value)
    bag = read_bag(out)
    assert bag.custom_data["ended"] == "interrupted by SIGINT" and not (tmp_path / "lib.partial").exists()
    for camera in CAMERAS:
        assert len(images(bag, camera)) == result["cameras"][camera]["frames"] > 0


def test_a_full_disk_stops_a_snapshot_with_a_valid_bag_of_what_it_kept(start_service, small_disk):
    svc = start_service("--camera", "a=synthetic:fps=25,width=640,height=480", "--history", "2")
    out = small_disk / "event"
    with Client(svc.endpoint) as client:
        wait_until(lambda: client.status()["cameras"]["a"]["frames_stored"] >= 52, what="2 s of history")
        with pytest.raises(DiskFull) as info:
            client.snapshot(before=2.0, after=0.0, out=str(out), cameras=["a"])  # 15 MB into an 8 MiB disk
        assert client.tuple()["a"].frame_id >= 0  # the service goes on
    assert "the snapshot stopped and kept" in str(info.value) and str(out) in str(info.value)
    kept = images(read_bag(out), "a")
    assert 0 < len(kept) == info.value.kept[rosmsgs.image_topic("a")]
    ids = [read_stamp(rosmsgs.image_array(m.msg)) for m in kept]
    assert ids == list(range(ids[0], ids[0] + len(ids)))
