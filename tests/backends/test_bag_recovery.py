"""The ``bag`` camera on a bag whose .mcap file was cut off (a recording killed, a copy
interrupted): it plays the complete messages, says how many, and leaves the file as it was."""

import hashlib
import os
import re

import pytest

from fxis_shm import read_stamp
from fxis_shm.formats import rosmsgs
from fxis_shm.formats.bagfile import BagReader

from ..integration.bags import cut_copy, frame_ids, message_ends, played_once, read_bag, record_a_cell

pytestmark = pytest.mark.integration
TOPIC = "/left/image_raw"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Two seconds of a two-camera cell, the recorded frame ids of the left camera, and where
    each message of the .mcap file ends."""
    bag = record_a_cell(tmp_path_factory.mktemp("cell"), "--seconds", "2")
    return bag, frame_ids(read_bag(bag), "left"), message_ends(bag / "bag_0.mcap")


def cut(recorded, out, fraction: float):
    """The bag cut at an arbitrary byte; the left frames and the messages left complete."""
    bag, ids, ends = recorded
    at = int(os.path.getsize(bag / "bag_0.mcap") * fraction) + 13
    mcap = cut_copy(bag, out, at)
    complete = [topic for end, topic in ends if end <= at]
    return mcap, ids[: complete.count(TOPIC)], len(complete)


def digest(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def test_a_cut_bag_is_read_as_far_as_it_is_complete_without_changing_it(recorded, tmp_path):
    mcap, left_ids, total = cut(recorded, tmp_path / "c", 0.55)
    before, files = digest(mcap), sorted(os.listdir(tmp_path / "c"))
    reader = BagReader(str(tmp_path / "c"))
    played = [read_stamp(rosmsgs.image_array(msg)) for _, msg in reader.messages(TOPIC)]
    assert played == left_ids and len(left_ids) > 5
    note = reader.damage(TOPIC)
    assert f"plays {len(left_ids)} of the file's {total} complete messages" in note
    assert re.search(r"the file ends in a torn record at byte \d+ \(\d+ bytes cut", note), note
    assert digest(mcap) == before and sorted(os.listdir(tmp_path / "c")) == files  # nothing written


def test_a_cut_bag_plays_as_a_camera_its_complete_frames_and_says_how_many(start_service, recorded, tmp_path):
    mcap, left_ids, total = cut(recorded, tmp_path / "c", 0.8)
    before = digest(mcap)
    svc = start_service("--camera", f"v=bag:path={tmp_path / 'c'},topic={TOPIC},loop=false,speed=4", "--slots", "64")
    with svc.client(timeout=5) as client:
        status, _ = played_once(client, "v", left_ids)
    assert f"plays {len(left_ids)} of the file's {total} complete messages" in status["note"]
    assert "torn record at byte" in status["note"]
    assert digest(mcap) == before
    log = (tmp_path / "service0.log").read_text()
    assert f"plays {len(left_ids)} of the file's {total} complete messages" in log and str(mcap) in log
