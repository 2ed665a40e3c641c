"""A video encoder never runs a thread at a real-time policy: SVT-AV1, run as root, sets the
thread that opens it, and the threads it starts, to SCHED_FIFO 99 (fxis_shm/formats/threadsched.py).
As another user SVT-AV1 leaves scheduling alone and these tests pass either way."""

import os
import threading

import numpy as np
import pytest

from fxis_shm.formats.threadsched import threads_of
from fxis_shm.formats.videochoice import DEFAULT_CRF, Choice
from fxis_shm.formats.videoencoder import CameraEncoder, StreamEncoder, opens

from ..conftest import wait_until

pytest.importorskip("av")
ENCODERS = [("h264", "libx264"), ("h265", "libx265"), ("av1", "libsvtav1")]


def real_time_threads() -> dict[int, tuple[int, int]]:
    return {tid: sched for tid, sched in threads_of("self").items() if sched[0] != os.SCHED_OTHER}


def frame(i: int) -> np.ndarray:
    return np.random.default_rng(i).integers(0, 256, (64, 96), dtype=np.uint8)


@pytest.mark.parametrize("codec, encoder", ENCODERS)
def test_a_recorders_encoder_thread_and_the_encoders_own_threads_stay_at_normal_priority(codec, encoder):
    """As ``fxis record --codec`` runs it: a CameraEncoder in its thread, fed from the caller's;
    looked at while the encoder is open (its library's threads alive) and after it finished."""
    camera = CameraEncoder(StreamEncoder("c", Choice(codec, encoder, False), DEFAULT_CRF[codec], None, 1.0, 20.0))
    packets = []
    for i in range(3):
        assert camera.offer(frame(i), i * 50_000_000, i, 0)
    wait_until(lambda: packets.extend(camera.ready()) or packets or camera.error, what="a first packet")
    assert camera.error is None
    assert real_time_threads() == {}  # open: the encoder's threads are running
    assert len(packets + camera.finish()) == 3
    assert real_time_threads() == {}


def test_the_encoder_probe_leaves_its_caller_at_normal_priority():
    """``opens`` (which `fxis record` and the snapshot ask before they choose an encoder) opens
    and encodes in the caller's thread."""
    assert opens(Choice("av1", "libsvtav1", False))
    assert os.sched_getscheduler(0) == os.SCHED_OTHER
    assert real_time_threads() == {}


def test_a_real_time_caller_is_given_back_its_own_policy():
    """A thread at SCHED_FIFO that opens an encoder stays at its priority, not SVT-AV1's 99,
    and the encoder's threads run at normal priority beside it."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(3))
    except PermissionError:  # the suite runs as root (CONTRIBUTING.md): every test runs, none is skipped
        pytest.fail("SCHED_FIFO is not allowed here: run the suite as root (or with CAP_SYS_NICE)")
    try:
        stream = StreamEncoder("c", Choice("av1", "libsvtav1", False), DEFAULT_CRF["av1"], None, 1.0, 20.0)
        stream.encode(frame(0), 0, 0, 0)
        assert real_time_threads() == {threading.get_native_id(): (os.SCHED_FIFO, 3)}
        stream.finish()
    finally:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
