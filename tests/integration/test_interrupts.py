"""Interrupted work keeps its data: SIGINT or SIGTERM sent to a real ``fxis snapshot``,
``fxis record`` or ``fxis grab`` at a random moment within its work (seeded; the seed is in
every failure's message: FXIS_TEST_SEED=N repeats it) leaves a valid bag or files holding what
was copied, metadata saying it was interrupted, one line saying what was kept, exit 130. A
kill -9 leaves what ``--recover`` repairs, and nothing deletes data of another run."""

from __future__ import annotations

import json
import os
import random
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from fxis_shm.client.snapshot import lost_to_ring
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagrecover import KILLED
from fxis_shm.formats.stamp import read_stamp

from ..conftest import wait_until
from .bags import kill_9_once_written, read_bag
from .conftest import module_service

pytestmark = pytest.mark.integration

SEED = int(os.environ.get("FXIS_TEST_SEED") or time.time_ns() % 1_000_000)
print(f"test_interrupts: FXIS_TEST_SEED={SEED}")
SIGNALS = [signal.SIGINT, signal.SIGTERM]


@pytest.fixture(scope="module")
def cell():
    """Two cameras with 3 s of history, 320x240 at 20 fps."""
    yield from module_service(
        [
            "--camera",
            "a=synthetic:fps=20,width=320,height=240",
            "--camera",
            "b=synthetic:fps=20,width=320,height=240,phase_ms=9",
            "--history",
            "3",
        ]
    )


def start(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        # faulthandler: an abort (a native library's) prints where each thread stood
        [sys.executable, "-X", "faulthandler", "-m", "fxis_shm.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def stop_with(proc: subprocess.Popen, sig: int, after_s: float) -> tuple[str, str]:
    """Sleeps ``after_s`` (the random moment), sends ``sig``; the command's stdout and stderr."""
    time.sleep(after_s)
    assert proc.poll() is None, f"the command ended before the signal (seed {SEED})"
    proc.send_signal(sig)
    try:
        return proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def moment(low: float, high: float, what: str) -> float:
    rng = random.Random(f"{SEED} {what}")
    chosen = rng.uniform(low, high)
    print(f"{what}: signal {chosen:.3f} s into the work (FXIS_TEST_SEED={SEED})")
    return chosen


def stamps_in_order(bag, camera: str) -> list[int]:
    ids = [read_stamp(rosmsgs.image_array(m.msg)) for m in bag.messages[rosmsgs.image_topic(camera)]]
    assert ids == sorted(ids) and None not in ids
    return ids


def interrupted_bag(proc, begun, sig, within: tuple[float, float], line: str):
    """Waits for the bag ``begun``, signals ``proc`` at a random moment ``within`` (s) after,
    checks exit 130 and the last line (a regex of the frames kept of a and b); the bag read
    back, its counts in the line, and stdout."""
    wait_until(begun.exists, timeout=30, what="the bag begun")
    command = proc.args[proc.args.index("fxis_shm.cli") + 1]
    stdout, stderr = stop_with(proc, sig, moment(*within, f"{command} {sig.name}"))
    assert proc.returncode == 130, (SEED, stderr)
    said = re.fullmatch(f"fxis {command}: interrupted by {sig.name}: {line}", stderr.strip().splitlines()[-1])
    assert said and "Traceback" not in stderr, (SEED, stderr)
    bag = read_bag(begun.parent if command == "record" else str(begun.parent).removesuffix(".partial"))
    assert bag.custom_data["ended"] == f"interrupted by {sig.name}"
    counts = [int(n) for n in said.groups()]
    assert [len(stamps_in_order(bag, camera)) for camera in "ab"] == counts and min(counts) > 0, SEED
    return bag, counts, stdout


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_a_snapshot_stopped_by_a_signal_keeps_a_valid_bag_of_what_it_copied(cell, tmp_path, sig):
    out = tmp_path / "s"
    proc = start("snapshot", "--endpoint", cell.endpoint, "--out", str(out), "--before", "1", "--after", "4")
    line = rf"the snapshot kept a (\d+) frames, b (\d+) frames in {re.escape(str(out))}, a valid bag"
    bag, counts, stdout = interrupted_bag(proc, tmp_path / "s.partial" / "s_0.mcap", sig, (0.3, 3.0), line)
    # the window's frames only, whenever the signal came (0.3 s in, a loaded machine may not have
    # copied the whole past second yet: make test saw 19 of 20; a camera starved for a while
    # captured nothing for it, so the first frame kept may lie well after the window's start)
    window_start = int(bag.custom_data["window_ns"].split()[0])
    for camera in "ab":
        stamp = bag.messages[rosmsgs.image_topic(camera)][0].msg.header.stamp
        assert stamp.sec * 10**9 + stamp.nanosec >= window_start, (camera, bag.custom_data)
    assert all(f"{camera}: {n} frames" in stdout for camera, n in zip("ab", counts)), stdout
    assert json.loads(bag.custom_data["missing"]).keys() == {"a", "b"}
    assert sorted(os.listdir(out)) == ["metadata.yaml", "s_0.mcap"] and not (tmp_path / "s.partial").exists()


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_a_recording_stopped_by_a_signal_keeps_a_valid_bag_and_exits_130(cell, tmp_path, sig):
    out = tmp_path / "r"
    proc = start("record", "--endpoint", cell.endpoint, "--out", str(out))
    line = rf"kept a (\d+) frames, b (\d+) frames, [\d.]+ s, in {re.escape(str(out))}, a valid bag"
    interrupted_bag(proc, out / "r_0.mcap", sig, (0.2, 2.5), line)


@pytest.fixture(scope="module")
def large():
    """Four cameras of large colour frames, so that a grab's PNGs take a while to write."""
    args = [a for i in range(4) for a in ("--camera", f"c{i}=synthetic:fps=5,width=1600,height=1200,pixel_format=bgr8")]
    yield from module_service(args)


def pngs(folder) -> list[str]:
    """The PNGs in ``folder`` so far. grab first checks that it can make the folder by making and
    removing it (fxis_shm/formats/outfolder.py), so the folder may vanish between a look that
    finds it and the listing (make test run 55: FileNotFoundError from Path.glob)."""
    try:
        return [name for name in os.listdir(folder) if name.endswith(".png")]
    except FileNotFoundError:
        return []


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: s.name)
def test_a_grab_stopped_by_a_signal_keeps_the_images_written_and_says_which(large, tmp_path, sig):
    out = tmp_path / "g"
    rng = random.Random(f"{SEED} grab {sig.name}")
    after = rng.randint(1, 3)  # the signal comes once this many of the 4 PNGs are there
    print(f"grab {sig.name}: signal after {after} of 4 images (FXIS_TEST_SEED={SEED})")
    proc = start("grab", "--endpoint", large.endpoint, "--out", str(out))
    wait_until(lambda: len(pngs(out)) >= after, timeout=30, interval=0.002, what="images written")
    stdout, stderr = stop_with(proc, sig, 0.0)
    assert proc.returncode == 130, (SEED, stdout, stderr)
    saved = sorted(p.name for p in out.glob("*.png"))
    assert after <= len(saved) < 4 and not list(out.glob("*.part")), (SEED, saved)
    last = stderr.strip().splitlines()[-1]
    assert last == (
        f"fxis grab: interrupted by {sig.name}: kept {', '.join(saved)} and tuple.json (naming them) in {out}"
    ), (SEED, stderr)
    meta = json.loads((out / "tuple.json").read_text())
    assert meta["ended"] == f"interrupted by {sig.name}"
    assert sorted(meta["frames"]) == [n[:-4] for n in saved] and len(meta["not_saved"]) == 4 - len(saved)
    import cv2

    for name in saved:
        image = cv2.imread(str(out / name), cv2.IMREAD_UNCHANGED)
        assert read_stamp(np.ascontiguousarray(image)) == meta["frames"][name[:-4]]["frame_id"]


def test_kill_9_leaves_a_partial_snapshot_that_a_rerun_keeps_and_recover_repairs(cell, tmp_path):
    out, partial = tmp_path / "k", tmp_path / "k.partial"
    proc = start("snapshot", "--endpoint", cell.endpoint, "--out", str(out), "--before", "0.5", "--after", "5")
    mcap = partial / "k_0.mcap"
    kill_9_once_written(proc, mcap, 2_000_000)
    size = mcap.stat().st_size
    again = start("snapshot", "--endpoint", cell.endpoint, "--out", str(out), "--before", "0.2", "--after", "0")
    _, stderr = again.communicate(timeout=30)
    assert again.returncode == 2, stderr
    assert stderr.strip() == (
        f"fxis snapshot: {partial} holds an unfinished snapshot (one that was stopped (killed?) left it); "
        f"nothing was changed: `fxis snapshot --recover {partial}` makes it the bag {out}, or remove it"
    )
    assert mcap.stat().st_size == size and not out.exists()  # the rerun touched nothing
    recover = start("snapshot", "--recover", str(partial))
    stdout, stderr = recover.communicate(timeout=60)
    assert recover.returncode == 0, stderr
    assert f"{out}: the snapshot's bag (renamed from {partial})" in stdout
    bag = read_bag(out)
    assert bag.custom_data["ended"] == KILLED and bag.custom_data["event_ns"]
    kept = [len(stamps_in_order(bag, camera)) for camera in "ab"]
    assert min(kept) > 0 and sum(kept) >= 10, kept  # the complete chunks of 2 MB of 77 kB frames


def test_a_second_snapshot_to_the_same_out_refuses_and_the_first_keeps_its_bag(cell, tmp_path):
    out = tmp_path / "twice"
    # the first runs until stopped: the second's start, however slow on a loaded machine, finds it writing
    first = start("snapshot", "--endpoint", cell.endpoint, "--out", str(out), "--before", "0.5", "--after", "60")
    wait_until(lambda: (tmp_path / "twice.partial").exists(), timeout=30, what="the first snapshot begun")
    second = start("snapshot", "--endpoint", cell.endpoint, "--out", str(out), "--before", "0.5", "--after", "0")
    _, stderr = second.communicate(timeout=30)
    assert second.returncode == 2 and "another snapshot is writing it now" in stderr, stderr
    _, stderr = stop_with(first, signal.SIGINT, 0.0)
    assert first.returncode == 130, stderr
    bag = read_bag(out)
    assert bag.custom_data["ended"] == "interrupted by SIGINT" and len(stamps_in_order(bag, "a")) >= 10  # 0.5 s before


def test_frames_the_ring_lost_before_the_first_look_are_named_missing():
    # the ring's oldest frame is id 100 at t=10 s; a 100 ms camera; the window 9.45 .. 10.25 s
    oldest = [100, 10_000_000_000, 0, 0, 0]
    assert lost_to_ring(oldest, 9_450_000_000, 10_250_000_000, 100_000_000) == [95, 96, 97, 98, 99]
    # a window wholly older than the ring: its frames by the ids the period gives them
    assert lost_to_ring(oldest, 9_000_000_000, 9_250_000_000, 100_000_000) == [90, 91, 92]
    assert lost_to_ring(oldest, 9_000_000_000, 9_250_000_000, 0) == []  # a triggered camera: no period


def test_a_second_grab_into_the_same_folder_replaces_nothing(cell, tmp_path):
    out = tmp_path / "g"
    first = start("grab", "--endpoint", cell.endpoint, "--out", str(out))
    assert first.wait(30) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    again = start("grab", "--endpoint", cell.endpoint, "--out", str(out))
    _, stderr = again.communicate(timeout=30)
    assert again.returncode == 2
    # refused before the service is asked (fxis_shm.formats.outfolder), one line
    assert stderr.startswith(f"fxis grab: --out {out}") and stderr.count("\n") == 1, stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_a_service_that_goes_away_mid_snapshot_leaves_a_valid_bag_of_what_was_copied(start_service, tmp_path):
    svc = start_service("--camera", "a=synthetic:fps=20,width=320,height=240", "--history", "2")
    with svc.client() as client:
        wait_until(lambda: client.status()["cameras"]["a"]["frames_stored"] >= 30, what="a second of history")
    out = tmp_path / "gone"
    proc = start("snapshot", "--endpoint", svc.endpoint, "--out", str(out), "--before", "1", "--after", "8")
    mcap = tmp_path / "gone.partial" / "gone_0.mcap"
    wait_until(lambda: mcap.exists() and mcap.stat().st_size > 1_000_000, timeout=30, what="the past copied")
    svc.stop()
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode not in (0, 130) and "Traceback" not in stderr, stderr
    kept = re.search(rf"fxis snapshot: the snapshot kept a (\d+) frames in {re.escape(str(out))}, a valid bag", stderr)
    assert kept, stderr
    bag = read_bag(out)
    assert bag.custom_data["ended"].startswith("stopped by an error: ")
    assert len(stamps_in_order(bag, "a")) == int(kept[1]) >= 10
