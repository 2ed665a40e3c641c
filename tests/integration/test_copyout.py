"""The coordinator's copies out of the rings into the ZeroMQ messages that carry them: one copy,
kept only if the seqlock shows the slot unchanged from before the copy to after it. (Against a
writer storing frames as fast as it can: test_faults.py's torn-read stress, through the service.)"""

import platform

import numpy as np
import pytest
import zmq

from fxis_shm import read_stamp
from fxis_shm.service.coordinator import as_message, keep_message_memory
from fxis_shm.shm.cameras import CameraHandle
from fxis_shm.shm.copyout import COPY, MESSAGES, CopyOut
from fxis_shm.shm.ring import FrameLayout, Overwritten, RingWriter
from tests.integration import test_ring

pytestmark = pytest.mark.integration

service = test_ring.service  # a service name whose segments are removed after the test
frame, LAYOUT = test_ring._frame, FrameLayout(64, 256)  # test_ring's frames of this layout, stamped


def image_of(message: zmq.Frame) -> np.ndarray:
    return np.frombuffer(message.buffer, np.uint8).reshape(LAYOUT.shape)


def test_a_reply_carries_each_distinct_frame_once_in_a_message_of_its_own(service):
    writer = RingWriter(service, "c", LAYOUT, 4)
    for k in range(3):
        writer.write(frame(k), k, 1000 * k)
    handle = CameraHandle(service, "c", "synthetic")
    handle.ring()
    out = CopyOut({"c": handle}, {}, message=as_message)
    snap = handle.snapshot()
    metas, images, position = out.copy({"c": snap}, [("c", 2), ("c", 0), ("c", 2)], MESSAGES)
    assert [m["frame_id"] for m in metas] == [2, 0] and [m["buffer"] for m in metas] == [0, 1]
    assert metas[0]["shape"] == list(LAYOUT.shape) and metas[0]["dtype"] == "uint8"
    assert position == {("c", 2): 0, ("c", 0): 1}
    assert all(isinstance(m, zmq.Frame) for m in images)
    writer.write(frame(3), 3, 3000)  # the ring moves on: the messages hold their own copies
    writer.write(frame(4), 4, 4000)
    np.testing.assert_array_equal(image_of(images[0]), frame(2))
    np.testing.assert_array_equal(image_of(images[1]), frame(0))
    # without a transport's messages, the pooled buffers (what a local client gets)
    _, pooled, _ = CopyOut({"c": handle}, {}).copy({"c": handle.snapshot()}, [("c", 0)], MESSAGES)
    assert isinstance(pooled[0], np.ndarray) and read_stamp(pooled[0]) == 1
    assert read_stamp(out.copy({"c": handle.snapshot()}, [("c", 3)], COPY)[1][0]) == 4
    out.message_max = LAYOUT.nbytes - 1  # frames larger than malloc keeps: the pool's buffers
    assert isinstance(out.copy({"c": handle.snapshot()}, [("c", 3)], MESSAGES)[1][0], np.ndarray)
    handle.close()
    writer.close()


def test_a_slot_overwritten_during_the_copy_is_refused_and_counted(service):
    writer = RingWriter(service, "c", LAYOUT, 2)
    for k in range(2):
        writer.write(frame(k), k, k)
    handle = CameraHandle(service, "c", "synthetic")
    handle.ring()
    snap = handle.snapshot()

    def overwritten_meanwhile(data):
        message = as_message(data)
        writer.write(frame(2), 2, 2)  # the writer reuses the slot while it is being copied
        return message

    out = CopyOut({"c": handle}, {}, message=overwritten_meanwhile)
    with pytest.raises(Overwritten):
        out.copy({"c": snap}, [("c", 0)], MESSAGES)
    assert handle.torn_reads == 1
    handle.close()
    writer.close()


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt's parameters are glibc's")
def test_malloc_is_told_to_keep_the_memory_of_sent_messages():
    assert keep_message_memory() is True  # elsewhere the coordinator sends from its buffer pool
