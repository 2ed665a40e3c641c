"""Recorded bags for the recording and replay tests: a small two-camera service, ``fxis
record`` run against it, and the bag read back with the independent ``rosbags`` library."""

from __future__ import annotations

import os
import shutil
import signal
import struct
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from mcap.reader import make_reader
from mcap.stream_reader import StreamReader
from rosbags.highlevel import AnyReader
from ruamel.yaml import YAML

from fxis_shm import read_stamp
from fxis_shm.formats import rosmsgs
from fxis_shm.service.launch import ServiceProcess

from ..conftest import assert_nothing_left, fxis, wait_until

FPS = 20
CAMERAS = [
    "left=synthetic:fps=20,width=160,height=120",
    "right=synthetic:fps=20,width=160,height=120,pixel_format=bgr8",
]


@dataclass
class Message:
    log_time: int
    msg: object

    @property
    def stamp(self) -> int:
        return rosmsgs.stamp_ns(self.msg.header.stamp)


@dataclass
class Bag:
    topics: dict  # topic -> message type
    messages: dict  # topic -> [Message], in log-time order
    custom_data: dict


def read_bag(path) -> Bag:
    """Everything in the bag, through rosbags (which reads metadata.yaml, then the MCAP)."""
    with AnyReader([Path(path)]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        messages = {t: [] for t in topics}
        for con, log_time, raw in reader.messages():
            messages[con.topic].append(Message(log_time, reader.deserialize(raw, con.msgtype)))
    # metadata.yaml parsed on its own, with the YAML library rosbags uses
    info = YAML(typ="safe").load(Path(path, "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return Bag(topics, messages, info.get("custom_data") or {})


def start_cameras(log_path) -> ServiceProcess:
    args = [a for cam in CAMERAS for a in ("--camera", cam)]
    return ServiceProcess(args, stderr=open(log_path, "w")).start()


def stop(svc: ServiceProcess) -> None:
    svc.stop()
    svc.stderr.close()
    assert_nothing_left(svc.name)


def record(svc: ServiceProcess, out, *args):
    """``fxis record`` against the service; fails the test if it fails."""
    result = fxis("record", "--endpoint", svc.endpoint, "--out", str(out), *args)
    assert result.returncode == 0, result.stderr
    assert os.path.exists(os.path.join(out, "metadata.yaml"))
    return result


def two_cameras(tmp_path_factory):
    """The two cameras, a service for a test module: ``cell = pytest.fixture(scope="module",
    name="cell")(two_cameras)``."""
    svc = start_cameras(tmp_path_factory.mktemp("svc") / "service.log")
    yield svc
    stop(svc)


def record_until_ctrl_c(svc: ServiceProcess, out: Path, written: int, *args) -> tuple[int, str, str]:
    """``fxis record ARGS`` interrupted by SIGINT once its .mcap file holds ``written`` bytes:
    (exit code, stdout, stderr)."""
    command = [sys.executable, "-m", "fxis_shm.cli", "record", "--endpoint", svc.endpoint, "--out", str(out), *args]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        mcap = out / f"{out.name}_0.mcap"
        wait_until(lambda: mcap.exists() and mcap.stat().st_size > written, timeout=30, what="frames recorded")
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        proc.kill()
        proc.wait()
    return proc.returncode, stdout, stderr


def record_a_cell(folder, *args) -> Path:
    """``fxis record ARGS`` of the two cameras, from a service of their own started and stopped
    for it, into ``folder``/bag."""
    svc = start_cameras(Path(folder, "service.log"))
    try:
        record(svc, Path(folder, "bag"), *args)
    finally:
        stop(svc)
    return Path(folder, "bag")


def frame_ids(bag: Bag, cam: str) -> list[int]:
    """The frame ids the synthetic camera stamped into the pixels of the bag's raw images."""
    return [read_stamp(rosmsgs.image_array(m.msg)) for m in bag.messages[f"/{cam}/image_raw"]]


def message_ends(mcap_path) -> list[tuple[int, str]]:
    """(the byte at which the message's record ends, its topic) for every message of a whole,
    uncompressed MCAP file, in file order, found through the file's own summary and message
    indexes read by the mcap library: what a cut at byte B leaves complete."""
    with open(mcap_path, "rb") as f:
        summary = make_reader(f).get_summary()
        ends = []
        for chunk in summary.chunk_indexes:
            assert chunk.compression == ""
            records = chunk.chunk_start_offset + 49  # opcode, length, 3 x u64, crc, "" and the records' length
            for channel, offset in chunk.message_index_offsets.items():
                f.seek(offset)
                index = next(StreamReader(f, skip_magic=True).records)
                for _, inner in index.records:
                    f.seek(records + inner + 1)
                    ends.append(
                        (records + inner + 9 + struct.unpack("<Q", f.read(8))[0], summary.channels[channel].topic)
                    )
    return sorted(ends)


def cut_copy(bag, out, at: int):
    """A copy of the bag folder ``bag`` at ``out`` whose .mcap file ends at byte ``at``."""
    shutil.copytree(bag, out)
    (mcap,) = Path(out).glob("*.mcap")
    os.truncate(mcap, at)
    return mcap


def played_once(client, camera: str, recorded_ids: list[int]):
    """Waits until the ``loop=false`` bag camera ``camera`` has played its bag; its status and
    its frames. Checks what holds on any machine: every frame stored is a recorded one, in the
    recorded order, and frames stored plus frames dropped (a loaded worker drops late ones)
    are the frames recorded."""
    status = wait_until(
        lambda: "end of bag" in (s := client.status()["cameras"][camera])["note"] and s,
        timeout=30,
        what=f"the end of {camera}'s bag",
    )
    frames = client.sequence("consecutive", camera=camera, count=status["frames_stored"])
    played = [read_stamp(f.image) for f in frames]
    assert len(played) == status["frames_stored"] > 0
    assert status["frames_stored"] + status["frames_dropped"] == len(recorded_ids)
    assert set(played) <= set(recorded_ids) and played == sorted(set(played)), (played, recorded_ids)
    return status, frames


def kill_9_once_written(proc, mcap: Path, size: int) -> None:
    """SIGKILL to ``proc`` once its bag file ``mcap`` holds ``size`` bytes (as a power cut would)."""
    try:
        wait_until(lambda: mcap.exists() and mcap.stat().st_size > size, timeout=30, what="chunks written")
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def record_across_a_size_change(svc: ServiceProcess, out: Path, camera: str, size: dict, *args) -> tuple[int, str, str]:
    """``fxis record ARGS`` (which must end by itself: --seconds or --frames) during which
    ``camera`` is restarted at ``size`` (``client.configure``, a new generation) once the
    recording has taken about 20 of its frames: (exit code, stdout, stderr)."""
    command = [sys.executable, "-m", "fxis_shm.cli", "record", "--endpoint", svc.endpoint, "--out", str(out), *args]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        with svc.client(timeout=5) as client:
            wait_until(lambda: Path(out, f"{out.name}_0.mcap").exists(), timeout=30, what="the recording's bag")
            first = client.image(camera).frame_id
            wait_until(lambda: client.image(camera).frame_id >= first + 20, timeout=30, what="20 frames recorded")
            assert client.configure(camera, **size)["cost"] == "restart"
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        proc.kill()
        proc.wait()
    return proc.returncode, stdout, stderr
