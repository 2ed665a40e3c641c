"""The recorder's pure decisions (which frames to take, what was missed) and its bag metadata."""

import json
import sys

import pytest

from fxis_shm.errors import ConfigError
from fxis_shm.formats import bagfile
from fxis_shm.record.recording import Follower, RestartGap, Steps, restart_record

P = 50_000_000  # a 20 fps camera


def rows(ids, generation=1):
    """``frames`` op rows: frame id k captured at k * P."""
    return [[k, k * P, k * P + 1, k * P + 1, generation] for k in ids]


def test_frames_are_taken_once_from_the_start_on():
    f = Follower(t_start=3 * P)
    assert [r[0] for r in f.new_frames(rows(range(0, 6)), P)] == [3, 4, 5]
    assert [r[0] for r in f.new_frames(rows(range(2, 9)), P)] == [6, 7, 8]
    assert f.new_frames(rows(range(2, 9)), P) == [] and f.missed == 0


def test_frames_that_left_the_ring_before_being_taken_are_missed():
    f = Follower(t_start=0)
    f.new_frames(rows(range(0, 5)), P)
    taken = f.new_frames(rows(range(12, 20)), P)  # the ring came round: 5..11 are gone
    assert taken[0][0] == 12 and f.missed == 7


def test_ids_the_camera_skipped_are_not_the_recorders_misses():
    f = Follower(t_start=0)
    f.new_frames(rows([0, 1, 2]), P)
    assert [r[0] for r in f.new_frames(rows([0, 1, 2, 5, 6]), P)] == [5, 6]  # 3, 4 dropped by the camera
    assert f.missed == 0


def test_a_restarted_camera_counts_afresh():
    f = Follower(t_start=0)
    f.new_frames(rows(range(0, 10)), P)
    restarted = [[k, (20 + k) * P, 0, 0, 2] for k in range(0, 3)]
    assert [r[0] for r in f.new_frames(restarted, P)] == [0, 1, 2] and f.missed == 0


def test_what_a_restart_cost_is_counted_by_ids_and_capture_times():
    """Issue 42, finding 7: frames 10..19 of the camera's time were never captured (the worker
    was down): the gap 9 P -> 20 P over the period P, less one."""
    f = Follower(t_start=0)
    f.new_frames(rows(range(0, 10)), P)
    f.new_frames([[k, (20 + k) * P, 0, 0, 2] for k in range(0, 3)], P)
    assert f.restarts == [RestartGap((1, 2), (9, 9 * P), (0, 20 * P), 10)] and f.missing_at_restarts == 10
    assert f.lost_to_restarts and f.missed == 0  # not the recorder's fault: counted apart
    assert f.restarts[0].describe() == (
        "generation 1 -> 2: 10 frames missing in 550 ms (after frame 9, before frame 0 of the next)"
    )
    f.new_frames([[k, (40 + k) * P, 0, 0, 3] for k in range(0, 3)], P)
    ended, gaps = restart_record({"a": f, "b": Follower(t_start=0)})
    assert ended == "frames missing where cameras restarted: a 27 frames in 2 restart(s)"
    assert [g["missing"] for g in json.loads(gaps)["a"]] == [10, 17] and "b" not in json.loads(gaps)


def test_a_restart_inside_one_listing_is_counted():
    """A restarted worker keeps its ring: one listing can hold frames of the old generation the
    recorder has not taken yet, then the first of the new one. The restart lies between two
    rows, not at the first (issue 42 finding 7: the recording said "complete", exit 0)."""
    f = Follower(t_start=0)
    f.new_frames(rows(range(0, 5)), P)
    listing = rows(range(0, 7)) + [[k, (20 + k) * P, 0, 0, 2] for k in range(0, 2)]
    assert [(r[4], r[0]) for r in f.new_frames(listing, P)] == [(1, 5), (1, 6), (2, 0), (2, 1)]
    assert f.restarts == [RestartGap((1, 2), (6, 6 * P), (0, 20 * P), 13)] and f.missed == 0


def test_frames_not_copied_because_the_camera_went_down_are_offered_again():
    """The camera went down between the listing and the copy: its frames are still in the ring,
    so they are taken after the restart, and the restart's gap starts at the last of them (the
    bag holds the frames either side of it)."""
    f = Follower(t_start=0)
    f.new_frames(rows(range(0, 5)), P)
    assert [r[0] for r in f.new_frames(rows(range(0, 8)), P)] == [5, 6, 7]
    f.give_back()  # the copy said CAMERA_DOWN
    listing = rows(range(0, 8)) + [[k, (20 + k) * P, 0, 0, 2] for k in range(0, 2)]
    assert [(r[4], r[0]) for r in f.new_frames(listing, P)] == [(1, 5), (1, 6), (1, 7), (2, 0), (2, 1)]
    assert f.restarts == [RestartGap((1, 2), (7, 7 * P), (0, 20 * P), 12)] and f.missed == 0


def test_a_frame_given_back_and_gone_from_the_ring_is_missed_once():
    f = Follower(t_start=0)
    f.new_frames(rows(range(0, 5)), P)
    f.new_frames(rows(range(8, 10)), P)  # 5..7 left the ring: missed
    f.give_back()
    assert [r[0] for r in f.new_frames(rows(range(9, 12)), P)] == [9, 10, 11]
    assert f.missed == 4  # 5..8, each once


def test_a_camera_without_a_period_cannot_say_what_a_restart_cost():
    f = Follower(t_start=0)
    f.new_frames(rows(range(0, 3)), 0)
    f.new_frames([[0, 30 * P, 0, 0, 2]], 0)
    assert f.restarts[0].missing is None and f.missing_at_restarts == 0 and f.lost_to_restarts
    assert "an unknown number of frames" in f.restarts[0].describe()
    assert restart_record({"a": Follower(t_start=0)}) == ("", "{}")  # none restarted: complete


def test_a_rate_thins_on_purpose_without_counting_misses():
    f = Follower(t_start=0, rate_hz=10)
    taken = f.new_frames(rows(range(0, 20)), P)
    assert [r[0] for r in taken] == list(range(0, 20, 2)) and f.missed == 0


def test_steps_come_due_and_those_the_rings_lost_are_missed():
    s = Steps(t0=0, rate_hz=10)
    assert s.due(now=250_000_000, oldest_held=0, limit=16) == [0, 100_000_000, 200_000_000]
    s.advance(3)
    # the recorder stalled: by now the rings hold frames from 0.65 s only
    assert s.due(now=1_000_000_000, oldest_held=650_000_000, limit=2) == [700_000_000, 800_000_000]
    assert s.missed == 4 and s.taken == 3


def test_metadata_yaml_is_yaml_that_rosbag2_readers_parse():
    from ruamel.yaml import YAML

    doc = {"a": {"b": 1, "c": "/x/image_raw"}, "l": [{"p": "f.mcap", "n": {"k": 2}}, "s"], "e": {}, "z": []}
    assert YAML(typ="safe").load(bagfile.to_yaml(doc)) == doc


def test_without_the_record_extra_the_error_names_it(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "mcap_ros2.writer", None)  # as if not installed
    with pytest.raises(ConfigError, match=r"extra 'record'.*fxis-shm\[record\]"):
        bagfile.BagWriter(str(tmp_path / "bag"))
