"""``fxis export BAG --lerobot OUT --fps HZ`` (issue 44, items 2 and 4): a recording made by a
real ``fxis run`` and ``fxis record`` (raw, JPEG and H.264 tracks) becomes a dataset that
lerobot 0.4.4's own LeRobotDataset loads from its local root, in its own venv (.venv-lerobot):
every frame of every camera decodes at its timestamp within LeRobot's tolerance_s, and the
frame decoded is the bag's frame of the capture time the dataset names (the frame id the
synthetic camera drew into its pixels says so). A slot no tuple fits is dropped and counted."""

import json
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from fxis_shm import read_stamp
from fxis_shm.formats import rosmsgs
from fxis_shm.wire import encoding

from ..conftest import fxis
from .bags import read_bag
from .test_lerobot import LEROBOT_PYTHON, ROOT, needs_venv

pytestmark = pytest.mark.integration

FPS = 30
# two mono cameras large enough for the drawn frame id to survive JPEG and H.264 (its blocks: 72x200 px)
CAMERAS = ["--camera", f"top=synthetic:fps={FPS},width=256,height=96"]
CAMERAS += ["--camera", f"side=synthetic:fps={FPS},phase_ms=9,width=256,height=96"]


def _record(start_service, out: Path, *args: str, cameras=CAMERAS) -> Path:
    svc = start_service(*cameras)
    done = fxis("record", "--endpoint", svc.endpoint, "--out", str(out), "--frames", "45", *args)
    assert done.returncode == 0, done.stderr
    return out


def _frame_ids(bag_path: Path, cam: str) -> dict[int, int]:
    """capture time -> frame id of each of the camera's frames, read with rosbags."""
    bag = read_bag(bag_path)
    if f"/{cam}/video/frames" in bag.messages:
        return {m.stamp: m.msg.frame_id for m in bag.messages[f"/{cam}/video/frames"]}
    if f"/{cam}/image_raw" in bag.messages:
        return {m.stamp: read_stamp(rosmsgs.image_array(m.msg)) for m in bag.messages[f"/{cam}/image_raw"]}
    jpeg = bag.messages[f"/{cam}/image_raw/compressed"]
    return {m.stamp: read_stamp(encoding.decode(bytes(m.msg.data), encoding.JPEG, None, None)) for m in jpeg}


def _load_in_lerobot(root: Path) -> dict:
    script = os.path.join(ROOT, "tests", "integration", "lerobot_dataset_reads.py")
    spec = {"root": str(root), "repo_id": f"fxis/{root.name}"}
    done = subprocess.run(
        [LEROBOT_PYTHON, script, json.dumps(spec)], capture_output=True, text=True, timeout=300, cwd=ROOT
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@needs_venv
@pytest.mark.parametrize("track", ["raw", "jpeg", "h264"])
def test_a_recording_exported_loads_in_lerobot_frame_by_frame_at_its_capture_times(start_service, tmp_path, track):
    bag = _record(start_service, tmp_path / "bag", "--encoding", track)
    out = tmp_path / "dataset"
    done = fxis("export", str(bag), "--lerobot", str(out), "--fps", str(FPS))
    assert done.returncode == 0, done.stderr
    info = json.loads((out / "meta" / "info.json").read_text())
    frames, fxis_info = info["total_frames"], info["fxis"]
    assert f"1 episode of {frames} frames at {FPS} fps" in done.stdout
    dropped = fxis_info["dropped_skew"] + fxis_info["dropped_far"]
    assert f"{dropped} of {fxis_info['slots']} slots dropped" in done.stdout
    assert "observations only" in done.stdout
    assert frames >= 40  # 45 frames a camera, 9 ms apart: every slot but an end one has its tuple

    seen = _load_in_lerobot(out)
    assert seen["num_frames"] == frames and seen["num_episodes"] == 1 and seen["fps"] == FPS
    assert seen["video_keys"] == ["observation.images.side", "observation.images.top"]
    ids = {cam: _frame_ids(bag, cam) for cam in ("top", "side")}
    t0, half_slot = fxis_info["t0_ns"], 5e8 / FPS
    for n, item in enumerate(seen["items"]):
        assert item["frame_index"] == item["index"] == n and item["episode_index"] == 0
        assert math.isclose(item["timestamp"], n / FPS, abs_tol=1e-6)
        extra = item["fxis"]
        slot_t = t0 + round(extra["observation.fxis.slot"] * 1e9 / FPS)
        for cam in ("top", "side"):
            key = f"observation.images.{cam}"
            assert item["shapes"][key] == [3, 96, 256]
            t_capture = extra[f"observation.fxis.t_capture.{cam}"]
            assert t_capture in ids[cam], f"frame {n}: {cam}'s capture time is none of the bag's"
            assert item["stamps"][key] == ids[cam][t_capture] & 0xFFFFFFFF, f"frame {n}: {cam} decoded another frame"
            assert extra[f"observation.fxis.skew_ns.{cam}"] == t_capture - slot_t
            assert abs(t_capture - slot_t) <= half_slot
        times = [extra[f"observation.fxis.t_capture.{cam}"] for cam in ("top", "side")]
        assert extra["observation.fxis.tuple_skew_ns"] == max(times) - min(times) <= fxis_info["max_skew_ms"] * 1e6
    slots = [item["fxis"]["observation.fxis.slot"] for item in seen["items"]]
    assert slots == sorted(set(slots))


def test_slots_without_a_tuple_within_the_bound_are_dropped_and_counted(start_service, tmp_path):
    """A camera at a third of the rate: of the slots at 30 fps, those more than half a slot
    from its frames are dropped (never filled with its last frame), and the count says so."""
    cameras = ["--camera", f"fast=synthetic:fps={FPS},width=64,height=48"]
    cameras += ["--camera", f"slow=synthetic:fps={FPS // 3},phase_ms=2,width=64,height=48"]
    svc = start_service(*cameras)
    bag = tmp_path / "bag"
    done = fxis("record", "--endpoint", svc.endpoint, "--out", str(bag), "--seconds", "2")
    assert done.returncode == 0, done.stderr
    out = tmp_path / "dataset"
    done = fxis("export", str(bag), "--lerobot", str(out), "--fps", str(FPS))
    assert done.returncode == 0, done.stderr
    info = json.loads((out / "meta" / "info.json").read_text())
    kept, slots = info["total_frames"], info["fxis"]["slots"]
    dropped = info["fxis"]["dropped_skew"] + info["fxis"]["dropped_far"]
    assert kept + dropped == slots and f"{dropped} of {slots} slots dropped" in done.stdout
    assert abs(kept - slots / 3) <= 2  # one slot in three lies near a frame of the slow camera
    import pyarrow.parquet as pq

    data = pq.read_table(out / "data" / "chunk-000" / "file-000.parquet").to_pydict()
    slow = data["observation.fxis.t_capture.slow"]
    assert len(set(slow)) == len(slow)  # no slow frame stands in for a later slot
    assert all(abs(skew) <= 5e8 / FPS for skew in data["observation.fxis.skew_ns.slow"])


@pytest.mark.parametrize(
    "args, said",
    [
        (["--fps", "0"], "--fps 0.0: give a whole number"),
        (["--fps", "-5"], "--fps -5.0: give a whole number"),
        (["--fps", "nan"], "--fps nan: give a whole number"),
        (["--fps", "29.97"], "--fps 29.97: give a whole number"),
        ([], "needs --fps HZ"),
        (["--fps", "30", "--camera", "top"], "leave out --camera and --out"),
        (["--fps", "30", "--max-skew-ms", "nan"], "--max-skew-ms nan"),
    ],
)
def test_bad_numbers_and_flags_exit_2_in_one_line(tmp_path, args, said):
    done = fxis("export", str(tmp_path / "no-bag"), "--lerobot", str(tmp_path / "out"), *args)
    assert done.returncode == 2 and said in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "out").exists()


def test_no_bag_or_an_existing_out_exits_2_in_one_line(tmp_path):
    done = fxis("export", str(tmp_path / "no-bag"), "--lerobot", str(tmp_path / "out"), "--fps", "30")
    assert done.returncode == 2 and "no bag at" in done.stderr and len(done.stderr.strip().splitlines()) == 1
    (tmp_path / "out").mkdir()
    done = fxis("export", str(tmp_path / "no-bag"), "--lerobot", str(tmp_path / "out"), "--fps", "30")
    assert done.returncode == 2 and "exists; give a new folder" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def _bag_with_joints(path: Path, offset_ns: int) -> tuple[list[int], list[int]]:
    """A bag as fxis record writes it (two cameras at 30 fps, stamps in the service's clock), plus
    the robot's joint states at 100 Hz (stamped in the wall clock, ``offset_ns`` ahead) with a
    gap of 0.3 s, and the leader arm's as the action; returns the joint messages' times."""
    from fxis_shm.formats.bagfile import BagWriter
    from fxis_shm.formats.stamp import write_stamp

    writer = BagWriter(str(path), {"clock": "CLOCK_MONOTONIC", "clock_to_realtime_ns": offset_ns})
    start = 5_000_000_000
    messages = []
    for i in range(60):
        for cam, phase in (("top", 0), ("side", 4_000_000)):
            t = start + phase + i * 33_333_333
            image = np.full((48, 64), 10 * (i % 20), np.uint8)
            write_stamp(image, i)
            messages.append((t, rosmsgs.image_topic(cam), rosmsgs.IMAGE, rosmsgs.image_message(image, t, cam)))
    state_times = [start + i * 10_000_000 for i in range(200) if not 80 <= i < 110]
    action_times = [start + i * 10_000_000 + 3_000_000 for i in range(200)]
    for topic, times in (("/robot/joint_states", state_times), ("/leader/joint_states", action_times)):
        for t in times:
            joint = {"header": rosmsgs.header(t + offset_ns, "arm"), "name": ["shoulder", "elbow"]}
            joint |= {"position": [t / 1e9, -t / 1e9], "velocity": [], "effort": []}
            messages.append((t, topic, rosmsgs.JOINT_STATE, joint))
    for t, topic, kind, message in sorted(messages, key=lambda m: m[0]):
        writer.write(topic, kind, message, t + offset_ns)
    writer.close()
    return state_times, action_times


def test_joint_states_become_state_and_action_at_the_same_slots(tmp_path):
    offset = 1_700_000_000_000_000_000
    state_times, action_times = _bag_with_joints(tmp_path / "bag", offset)
    out = tmp_path / "dataset"
    args = ["--fps", "30", "--action-topic", "/leader/joint_states", "--state-topic", "/robot/joint_states"]
    done = fxis("export", str(tmp_path / "bag"), "--lerobot", str(out), *args)
    assert done.returncode == 0, done.stderr
    assert "observation.state from /robot/joint_states; action from /leader/joint_states" in done.stdout
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["features"]["observation.state"] == {"dtype": "float32", "shape": [2], "names": ["shoulder", "elbow"]}
    dropped = info["fxis"]["dropped_joints"]
    assert 7 <= dropped <= 9 and f"no joint state near it: {dropped}" in done.stdout  # the 0.3 s gap, at 30 fps
    import pyarrow.parquet as pq

    data = pq.read_table(out / "data" / "chunk-000" / "file-000.parquet").to_pydict()
    for n, slot in enumerate(data["observation.fxis.slot"]):
        t_slot = info["fxis"]["t0_ns"] + round(slot * 1e9 / FPS)
        t_state, t_action = data["observation.fxis.t_state"][n], data["observation.fxis.t_action"][n]
        assert t_state == min(state_times, key=lambda t: abs(t - t_slot))  # the nearest, in the bag's clock
        assert t_action == min(action_times, key=lambda t: abs(t - t_slot))
        assert data["observation.state"][n] == pytest.approx([t_state / 1e9, -t_state / 1e9], rel=1e-6)
        assert data["action"][n] == pytest.approx([t_action / 1e9, -t_action / 1e9], rel=1e-6)


def test_several_joint_state_topics_need_one_named(tmp_path):
    _bag_with_joints(tmp_path / "bag", 0)
    done = fxis("export", str(tmp_path / "bag"), "--lerobot", str(tmp_path / "out"), "--fps", "30")
    assert done.returncode == 2 and "several JointState topics" in done.stderr and not (tmp_path / "out").exists()
