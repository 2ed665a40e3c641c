"""``fxis record`` when things go wrong: a disk that fills, a recorder killed with kill -9,
a bag cut off at any byte. Real processes and files; every bag read back with rosbags."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from ruamel.yaml import YAML

from fxis_shm.formats.bagrecover import KILLED

from ..conftest import fxis
from .bags import cut_copy, frame_ids, kill_9_once_written, message_ends, read_bag, record, start_cameras, stop

pytestmark = pytest.mark.integration
CAMS = ("left", "right")
KEPT = re.compile(
    r"No space left on device in (\S+): the recording stopped and kept left (\d+) frames, "
    r"right (\d+) frames, ([\d.]+) s, ([\d.]+) MB, in a valid bag$"
)


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    svc = start_cameras(tmp_path_factory.mktemp("svc") / "service.log")
    yield svc
    stop(svc)


def counts_in_metadata(out) -> dict:
    info = YAML(typ="safe").load(Path(out, "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}


def camera_drops(svc) -> dict[str, int]:
    with svc.client() as client:
        return {cam: info["frames_dropped"] for cam, info in client.status()["cameras"].items()}


def assert_every_frame_in_order(bag, dropped: dict[str, int], cams=CAMS) -> None:
    """Each camera's images in order, and none lost in between but the frames its camera
    dropped meanwhile (``dropped``: counted in its status; a worker held up past its driver's
    buffers on a busy machine drops some, and the recorder cannot record those)."""
    for cam in cams:
        stamps = [m.stamp for m in bag.messages[f"/{cam}/image_raw"]]
        assert all(b > a for a, b in zip(stamps, stamps[1:]))
        ids = frame_ids(bag, cam)  # the pixels name the frame
        assert all(b > a for a, b in zip(ids, ids[1:])), ids
        assert ids[-1] - ids[0] + 1 - len(ids) <= dropped[cam], (ids, dropped)


def test_a_full_disk_stops_the_recording_with_a_valid_bag_and_says_what_it_kept(cell, small_disk):
    out = small_disk / "bag"
    before = camera_drops(cell)
    result = fxis("record", "--endpoint", cell.endpoint, "--out", str(out), timeout=120)
    assert result.returncode == 4, result.stderr  # failed at run time, the bag kept (docs/cli.md)
    assert "Traceback" not in result.stderr
    last = result.stderr.strip().splitlines()[-1]
    kept = KEPT.search(last)
    assert kept and last.startswith("fxis record: ") and kept[1] == str(out), result.stderr
    assert result.stderr.count("No space left") == 1 and result.stdout == ""  # one line, no table
    left, right, seconds, megabytes = int(kept[2]), int(kept[3]), float(kept[4]), float(kept[5])
    assert left > 20 and right > 20  # seconds of frames fitted in 8 MiB
    bag = read_bag(out)
    assert len(bag.messages["/left/image_raw"]) == left and len(bag.messages["/right/image_raw"]) == right
    assert counts_in_metadata(out) == {"/left/image_raw": left, "/right/image_raw": right}
    after = camera_drops(cell)
    assert_every_frame_in_order(bag, {cam: after[cam] - before[cam] for cam in CAMS})
    assert bag.custom_data["ended"] == "the disk was full (No space left on device): closed with what fitted"
    every = sorted(m.log_time for msgs in bag.messages.values() for m in msgs)
    assert abs((every[-1] - every[0]) / 1e9 - seconds) < 0.06
    assert abs(os.path.getsize(out / "bag_0.mcap") / 1e6 - megabytes) < 0.06
    assert sorted(os.listdir(out)) == ["bag_0.mcap", "metadata.yaml"]  # the reserve is gone


def test_kill_9_then_recover_makes_the_bag_readable_up_to_its_last_complete_message(cell, tmp_path):
    out = tmp_path / "k"
    before = camera_drops(cell)
    with open(tmp_path / "record.log", "w") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "fxis_shm.cli", "record", "--endpoint", cell.endpoint, "--out", str(out)],
            stdout=log,
            stderr=log,
        )
        kill_9_once_written(proc, out / "k_0.mcap", 3_000_000)
    after = camera_drops(cell)
    assert not (out / "metadata.yaml").exists()
    with pytest.raises(FileNotFoundError, match="metadata"):  # rosbags refuses it as it is
        read_bag(out)
    result = fxis("record", "--recover", str(out))
    assert result.returncode == 0, result.stderr
    bag = read_bag(out)
    counts = {t: len(m) for t, m in bag.messages.items()}
    assert counts_in_metadata(out) == counts and all(n > 10 for n in counts.values()), counts
    assert_every_frame_in_order(bag, {cam: after[cam] - before[cam] for cam in CAMS})
    total = sum(counts.values())
    assert f"recovered {total} messages over" in result.stdout
    for topic, n in counts.items():
        assert re.search(rf"^  {topic}\s+{n}\s+sensor_msgs/msg/Image$", result.stdout, re.M), result.stdout
    assert "k_0.mcap.damaged" in result.stdout and (out / "k_0.mcap.damaged").exists()
    assert not (out / ".fxis-reserve").exists()
    assert bag.custom_data["ended"] == KILLED and bag.custom_data["clock"] == "CLOCK_MONOTONIC"
    again = fxis("record", "--recover", str(out))
    assert again.returncode == 0 and "the bag is whole" in again.stdout


@pytest.fixture(scope="module")
def whole_bag(cell, tmp_path_factory):
    out = tmp_path_factory.mktemp("whole") / "w"
    record(cell, out, "--seconds", "1.5")
    return out, message_ends(out / "w_0.mcap")


@pytest.mark.parametrize("where", [0.1, 0.37, 0.5, 0.83, 0.999])
def test_recover_keeps_exactly_the_complete_messages_of_a_bag_cut_at_any_byte(whole_bag, tmp_path, where):
    out, ends = whole_bag
    size = os.path.getsize(out / "w_0.mcap")
    at = int(size * where) + 7
    mcap = cut_copy(out, tmp_path / "cut", at)
    os.remove(tmp_path / "cut" / "metadata.yaml")
    result = fxis("record", "--recover", str(tmp_path / "cut"))
    assert result.returncode == 0, result.stderr
    expected = {}
    for end, topic in ends:
        if end <= at:
            expected[topic] = expected.get(topic, 0) + 1
    bag = read_bag(tmp_path / "cut")
    assert {t: len(m) for t, m in bag.messages.items() if m} == expected
    whole = read_bag(out)
    for topic, n in expected.items():  # the first n messages, as recorded, each the frame it was
        assert [m.log_time for m in bag.messages[topic]] == [m.log_time for m in whole.messages[topic][:n]]
        cam = topic.split("/")[1]
        assert frame_ids(bag, cam) == frame_ids(whole, cam)[:n]
    assert os.path.getsize(str(mcap) + ".damaged") == at  # the original, untouched
    assert "torn record at byte" in result.stdout or "nothing cut" in result.stdout


def test_recover_of_what_is_no_bag_says_so(tmp_path):
    result = fxis("record", "--recover", str(tmp_path / "nothing"))
    assert result.returncode == 2 and "no bag at" in result.stderr
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "x_0.mcap").write_bytes(b"not an mcap file at all")
    result = fxis("record", "--recover", str(tmp_path / "x"))
    assert result.returncode == 2 and "not an MCAP file" in result.stderr
    assert (tmp_path / "x" / "x_0.mcap").read_bytes() == b"not an mcap file at all"
    result = fxis("record", "--recover", str(tmp_path / "x"), "--seconds", "3")
    assert result.returncode == 2 and "--recover repairs a bag: it takes no --seconds" in result.stderr
