"""``fxis export BAG --lerobot OUT --fps HZ``: a recording of ``fxis record`` (raw, JPEG or
video tracks) as a LeRobotDataset v3.0 folder of one episode (docs/lerobot.md).

The bag is resampled on the grid ``t0 + k/fps`` by fxis's own joint selection
(fxis_shm.record.lerobotslots); each kept slot is one frame of the dataset. LeRobot needs
``timestamp = frame_index / fps`` with frames 1/fps apart, so a dropped slot leaves no row:
the frames after it move up one place, and ``observation.fxis.slot`` keeps each frame's slot
number k (its time on the grid is t0 + k/fps). Per camera, ``observation.fxis.t_capture.CAM``
is the true capture time of its frame (ns, the bag's clock, named in meta/info.json's
``fxis``) and ``observation.fxis.skew_ns.CAM`` that time minus the slot's.

Where the bag holds a robot's ``sensor_msgs/msg/JointState`` (fxis_shm.record.bagjoints),
``observation.state`` (and ``action``, from a topic named) are its joint positions at each
slot; a bag of ``fxis record`` alone holds images only, and then the dataset has observations
only, no ``observation.state`` or ``action``, and the export says so.
"""

from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass

import numpy as np

from fxis_shm.errors import ConfigError, InvalidArgument
from fxis_shm.formats.bagfile import RECORD, BagReader
from fxis_shm.record import lerobotfiles as files
from fxis_shm.record.bagframes import CameraTrack, camera_tracks, images
from fxis_shm.record.bagjoints import JointTrack, choose_topics, joint_track
from fxis_shm.record.lerobotslots import Grid, Slot, slot_grid

IMAGE_KEY = "observation.images.{}"
T_CAPTURE_KEY = "observation.fxis.t_capture.{}"
SKEW_KEY = "observation.fxis.skew_ns.{}"
SLOT_KEY = "observation.fxis.slot"
TUPLE_SKEW_KEY = "observation.fxis.tuple_skew_ns"
JOINT_KEYS = {"observation.state": "observation.fxis.t_state", "action": "observation.fxis.t_action"}


@dataclass
class ExportOptions:
    fps: float
    max_skew_ms: float | None = None  # default: half a slot period
    task: str | None = None  # default: "fxis recording BAGNAME"
    state_topic: str | None = None  # default: the bag's one JointState topic, if it has one
    action_topic: str | None = None


@dataclass
class LeRobotExported:
    out: str
    frames: int
    grid: Grid
    cameras: list[str]
    fps: int
    max_skew_ms: float
    clock: str
    joints: dict[str, str]  # "observation.state" / "action" -> the topic sampled


def check_fps(fps: float) -> int:
    """The dataset's frame rate: LeRobot keeps a whole number of frames per second."""
    if not math.isfinite(fps) or fps <= 0 or fps != int(fps):
        raise InvalidArgument(f"--fps {fps}: give a whole number of frames per second > 0 (LeRobot's fps)")
    return int(fps)


def default_max_skew_ms(fps: int) -> float:
    """Half a slot period: a tuple more skewed than that spans more than one slot's share."""
    return 500.0 / fps


def export_lerobot(bag_path: str, out: str, options: ExportOptions) -> LeRobotExported:
    """Write the dataset ``out`` (a new folder) of the bag ``bag_path``; ConfigError for a bag
    this cannot export, InvalidArgument for bad numbers or an ``out`` that exists."""
    rate = check_fps(options.fps)
    bound_ms = default_max_skew_ms(rate) if options.max_skew_ms is None else options.max_skew_ms
    if not math.isfinite(bound_ms) or bound_ms <= 0:
        raise InvalidArgument(f"--max-skew-ms {options.max_skew_ms}: give a number of milliseconds > 0")
    if os.path.lexists(out):
        raise InvalidArgument(f"--lerobot {out}: exists; give a new folder name")
    files.require_pyarrow()
    bag = BagReader(bag_path)
    tracks = camera_tracks(bag)
    state, action = choose_topics(bag, options.state_topic, options.action_topic)
    named = {"observation.state": state, "action": action}
    joints = {key: joint_track(bag, topic) for key, topic in named.items() if topic}
    grid = slot_grid({t.camera: t.times for t in tracks}, rate, round(bound_ms * 1e6))
    grid, joint_rows = _with_joints(grid, joints, 5e8 / rate)
    if not grid.slots:
        raise ConfigError(
            f"{bag.path}: none of the {grid.total} slots at {rate} fps has a tuple within {bound_ms:g} ms "
            "(raise --max-skew-ms, or lower --fps)"
        )
    clock = bag.metadata.get(RECORD, {}).get("clock", "the bag's clock")
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    try:
        task = options.task or f"fxis recording {os.path.basename(os.path.normpath(bag_path))}"
        features = _write(bag, tracks, grid, out, rate, task, joints, joint_rows)
        fxis = _provenance(tracks, grid, rate, bound_ms, clock, bag.path, joints)
        files.write_info(out, rate, len(grid.slots), features, fxis)
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)  # half a dataset is no export
        raise
    topics = {key: track.topic for key, track in joints.items()}
    return LeRobotExported(out, len(grid.slots), grid, [t.camera for t in tracks], rate, bound_ms, clock, topics)


def _with_joints(grid: Grid, joints: dict[str, JointTrack], within_ns: float) -> tuple[Grid, dict[str, list[int]]]:
    """The grid less the slots some joint track has no message near; per track, the message
    of each slot kept."""
    kept: list[Slot] = []
    rows: dict[str, list[int]] = {key: [] for key in joints}
    for slot in grid.slots:
        near = {key: track.nearest(slot.t_ns, within_ns) for key, track in joints.items()}
        if any(i is None for i in near.values()):
            continue
        kept.append(slot)
        for key, i in near.items():
            rows[key].append(i)  # type: ignore[arg-type]  # (None was left out above)
    dropped = len(grid.slots) - len(kept)
    return Grid(kept, grid.total, grid.dropped_skew, grid.dropped_far, dropped), rows


def _write(bag, tracks: list[CameraTrack], grid: Grid, out: str, fps: int, task: str, joints, joint_rows) -> dict:
    """The videos, data, tasks, episode and stats; returns the features for meta/info.json."""
    os.makedirs(os.path.join(out, "meta"))
    n = len(grid.slots)
    columns: dict[str, np.ndarray] = {}
    stats: dict = {}
    features: dict = {}
    names: dict[str, list[str] | None] = {}
    for track in tracks:
        key = IMAGE_KEY.format(track.camera)
        video = None
        for picture in images(bag, track, [s.index[track.camera] for s in grid.slots]):
            if video is None:
                height, width = picture.shape[:2]
                path = os.path.join(out, "videos", key, files.CHUNK + ".mp4")
                video = files.VideoWriter(path, fps, width, height)
                features[key] = files.video_feature(height, width, fps)
            video.add(picture)
        assert video is not None  # a kept slot has a frame of every camera
        video.close()
        stats[key] = video.stats.as_dict()
        t_capture = np.array([s.t_capture[track.camera] for s in grid.slots], np.int64)
        columns[T_CAPTURE_KEY.format(track.camera)] = t_capture
        columns[SKEW_KEY.format(track.camera)] = t_capture - np.array([s.t_ns for s in grid.slots], np.int64)
    for key, joint in joints.items():
        rows = joint_rows[key]
        columns[key], names[key] = joint.positions[rows], joint.names
        columns[JOINT_KEYS[key]] = np.array([joint.times[i] for i in rows], np.int64)
    columns[SLOT_KEY] = np.array([s.k for s in grid.slots], np.int64)
    columns[TUPLE_SKEW_KEY] = np.array([s.skew_ns for s in grid.slots], np.int64)
    frame_index = np.arange(n, dtype=np.int64)
    columns["timestamp"] = (frame_index / fps).astype(np.float32)
    columns |= {"frame_index": frame_index, "episode_index": np.zeros(n, np.int64), "index": frame_index}
    columns["task_index"] = np.zeros(n, np.int64)
    files.write_data(out, columns)
    for name, values in columns.items():
        shape = [values.shape[1]] if values.ndim == 2 else [1]
        features[name] = {"dtype": values.dtype.name, "shape": shape, "names": names.get(name)}
        stats[name] = files.column_stats(values)
    files.write_tasks(out, [task])
    files.write_episode(out, [task], n, fps, [IMAGE_KEY.format(t.camera) for t in tracks])
    files.write_stats(out, stats)
    return features


def _provenance(tracks, grid: Grid, fps: int, bound_ms: float, clock: str, bag_path: str, joints) -> dict:
    """meta/info.json's ``fxis``: where the dataset came from and how it was resampled."""
    first = grid.slots[0]
    return {
        "bag": bag_path,
        "clock": clock,
        "t_capture_unit": "ns",
        "t0_ns": first.t_ns - round(first.k * 1e9 / fps),
        "grid": f"slot k at t0 + k/fps; {SLOT_KEY} is each frame's k",
        "max_skew_ms": bound_ms,
        "slots": grid.total,
        "dropped_skew": grid.dropped_skew,
        "dropped_far": grid.dropped_far,
        "dropped_joints": grid.dropped_joints,
        "cameras": {t.camera: t.kind for t in tracks},
        "joints": {key: track.topic for key, track in joints.items()} or "none: the bag holds observations only",
    }
