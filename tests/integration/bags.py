"""Recorded bags for the recording and replay tests: a small two-camera service, ``fxis
record`` run against it, and the bag read back with the independent ``rosbags`` library."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from rosbags.highlevel import AnyReader
from ruamel.yaml import YAML

from fxis_shm.formats import rosmsgs
from fxis_shm.service.launch import ServiceProcess

from ..conftest import assert_nothing_left, fxis

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
