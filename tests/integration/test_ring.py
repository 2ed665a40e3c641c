"""The shared-memory ring with real segments: order, overwrite detection,
generations, permissions, and a concurrent writer process."""

import multiprocessing
import os
import random
import stat

import numpy as np
import pytest

from fxis_shm import read_stamp
from fxis_shm.core.snapshot import CAPTURE_LOCKSTEP, CAPTURE_SCHEDULED, CAPTURES
from fxis_shm.errors import RingError
from fxis_shm.formats.stamp import write_stamp
from fxis_shm.shm import naming
from fxis_shm.shm.ring import FrameLayout, Overwritten, RingReader, RingWriter

pytestmark = pytest.mark.integration

LAYOUT = FrameLayout(8, 32)


@pytest.fixture
def service(request):
    name = f"ring{os.getpid()}{abs(hash(request.node.name)) % 10000}"
    yield name
    naming.remove_leftovers(name)


def frame(k):
    image = np.full(LAYOUT.shape, k % 256, np.uint8)
    write_stamp(image, k)
    return image


def test_reader_sees_frames_in_order_across_the_wrap(service):
    writer = RingWriter(service, "c", LAYOUT, 4)
    reader = RingReader(service, "c")
    for k in range(11):
        writer.write(frame(k), k, 1000 * k)
    snap = reader.snapshot()
    assert [snap.timeline.at(i) for i in range(len(snap.timeline))] == [7000, 8000, 9000, 10000]
    for i in range(4):
        assert read_stamp(reader.copy(snap, i)) == snap.frame_meta(i).frame_id == 7 + i
    reader.close()
    writer.close()


def test_the_delay_rises_at_once_with_a_late_frame_and_falls_back_smoothly(service):
    """A worker catching up stores frames late: the ring's delay follows at once (requests then
    wait for its frames rather than give them up), and eases back as frames come on time."""
    from fxis_shm.core import timebase

    writer = RingWriter(service, "c", LAYOUT, 4)
    reader = RingReader(service, "c")
    ms = 1_000_000
    for k in range(40):  # on time: stored within a few ms of capture
        writer.write(frame(k), k, timebase.now())
    on_time = reader.timing()[1]
    assert 0 <= on_time < 5 * ms
    writer.write(frame(40), 40, timebase.now() - 200 * ms)  # held 200 ms in the driver's buffers
    assert reader.timing()[1] >= 200 * ms
    writer.write(frame(41), 41, timebase.now())
    assert 150 * ms < reader.timing()[1] < 200 * ms  # one frame on time: a sixteenth of the way back
    reader.close()
    writer.close()


def test_each_frame_keeps_how_it_was_captured(service):
    """A frame triggered for a moment keeps that moment and how (scheduled, lockstep) in its slot
    record; a free one says free with no target. Readers see it through every path."""
    writer = RingWriter(service, "c", LAYOUT, 4)
    reader = RingReader(service, "c")
    writer.write(frame(0), 0, 1000)
    writer.write(frame(1), 1, 2000, None, 1990, CAPTURE_SCHEDULED)
    writer.write(frame(2), 2, 3000, None, 3003, CAPTURE_LOCKSTEP)
    snap = reader.snapshot()
    got = [(m.t_target, CAPTURES[m.capture]) for m in (snap.frame_meta(i) for i in range(3))]
    assert got == [(0, "free"), (1990, "scheduled"), (3003, "lockstep")]
    reader.close()
    writer.close()


def test_empty_and_partly_filled_rings(service):
    writer = RingWriter(service, "c", LAYOUT, 4)
    reader = RingReader(service, "c")
    assert len(reader.snapshot().timeline) == 0
    writer.write(frame(0), 0, 5)
    snap = reader.snapshot()
    assert len(snap.timeline) == 1 and snap.newest == 5
    reader.close()
    writer.close()


def test_a_frame_overwritten_after_the_snapshot_is_refused(service):
    writer = RingWriter(service, "c", LAYOUT, 2)
    reader = RingReader(service, "c")
    for k in range(2):
        writer.write(frame(k), k, k)
    snap = reader.snapshot()
    writer.write(frame(2), 2, 2)  # reuses the slot of frame 0
    with pytest.raises(Overwritten):
        reader.copy(snap, 0)
    assert read_stamp(reader.copy(snap, 1)) == 1
    reader.close()
    writer.close()


def test_generation_grows_on_reattach_and_on_a_new_layout(service):
    generations = []
    for layout in (LAYOUT, LAYOUT, FrameLayout(8, 64)):
        writer = RingWriter(service, "c", layout, 4)
        generations.append(writer.generation)
        writer.close()
    assert generations == [1, 2, 3]


def test_reattached_writer_keeps_stored_frames(service):
    writer = RingWriter(service, "c", LAYOUT, 4)
    for k in range(3):
        writer.write(frame(k), k, k)
    writer.close()
    writer = RingWriter(service, "c", LAYOUT, 4)
    writer.write(frame(3), 3, 3)
    reader = RingReader(service, "c")
    snap = reader.snapshot()
    gens = [snap.frame_meta(i).generation for i in range(len(snap.timeline))]
    assert gens == [1, 1, 1, 2]
    reader.close()
    writer.close()


def test_a_reader_notices_a_retired_ring(service):
    writer = RingWriter(service, "c", LAYOUT, 4)
    reader = RingReader(service, "c")
    writer.close()
    RingWriter(service, "c", FrameLayout(4, 32), 4).close()
    assert reader.retired
    assert RingReader(service, "c").layout == FrameLayout(4, 32)
    reader.close()


def test_segments_are_private_to_the_user(service):
    writer = RingWriter(service, "c", LAYOUT, 4)
    for path in naming.leftovers(service):
        assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    writer.close()


def test_missing_ring_is_a_clear_error(service):
    with pytest.raises(RingError, match="does not exist"):
        RingReader(service, "nothing")


def _frame(k: int) -> np.ndarray:
    image = np.full((64, 256), k % 256, np.uint8)
    write_stamp(image, k)
    return image


def _write_fast(service, count):
    writer = RingWriter(service, "c", FrameLayout(64, 256), 2)
    for k in range(count):
        writer.write(_frame(k), k, k)
    writer.close()


def test_concurrent_writer_never_yields_a_torn_copy(service):
    RingWriter(service, "c", FrameLayout(64, 256), 2).close()
    reader = RingReader(service, "c")
    writer = multiprocessing.get_context("spawn").Process(target=_write_fast, args=(service, 20000))
    writer.start()
    good = torn = 0
    while writer.is_alive() or good == 0:
        snap = reader.snapshot()
        if not len(snap.timeline):
            continue
        i = len(snap.timeline) - 1
        try:
            image = reader.copy(snap, i)
        except Overwritten:
            torn += 1
            continue
        assert read_stamp(image) == snap.frame_meta(i).frame_id
        np.testing.assert_array_equal(image, _frame(snap.frame_meta(i).frame_id))  # every pixel of one frame
        good += 1
    writer.join(30)
    assert writer.exitcode == 0 and good > 0
    reader.close()


def _frames_of(snap):
    return [(snap.seq(i), snap.frame_meta(i), snap.timeline.at(i)) for i in range(len(snap.timeline))]


def test_a_snapshot_kept_up_to_date_equals_one_read_whole(service):
    """A reader reads only the slot records written since its last look: what it shows must be
    what a reader reading the whole table for the first time shows, through wraps and laps."""
    rng = random.Random(7)
    writer = RingWriter(service, "c", LAYOUT, 5)
    steady = RingReader(service, "c")
    k = 0
    for _ in range(80):
        for _ in range(rng.choice([0, 0, 1, 1, 2, 4, 5, 9])):
            writer.write(frame(k), k, 1000 * k + rng.randrange(500))
            k += 1
        fresh = RingReader(service, "c")
        kept, whole = steady.snapshot(), fresh.snapshot()
        fresh.close()
        assert (kept.first_write, _frames_of(kept)) == (whole.first_write, _frames_of(whole))
        if kept is not steady.snapshot():  # nothing new: the same snapshot again
            raise AssertionError("a look with nothing new made a new snapshot")
    steady.close()
    writer.close()
