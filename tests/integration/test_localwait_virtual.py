"""The same-host client's wait for a frame, in virtual time: real rings in this process, a
scripted writer, and a clock that moves only when the client sleeps (issue 41).

The client's sleeps advance the clock, and the writer stores each scripted frame at its
moment within them: the interleaving of writer and reader is exact, whatever the machine's
load. How soon a wait ends on a real machine is measured by bench/latency/wake.py."""

import os
import types

import numpy as np
import pytest

from fxis_shm.client import localreads
from fxis_shm.client.localreads import LocalReads
from fxis_shm.core import timebase
from fxis_shm.shm import naming
from fxis_shm.shm.localpath import boot_id, time_namespace
from fxis_shm.shm.ring import FrameLayout, RingWriter

pytestmark = pytest.mark.integration

PERIOD = 50_000_000  # 20 fps
MS = 1_000_000
T0 = 10**12  # the virtual clock's start


class Script:
    """A virtual clock and the frames a camera worker stores at given moments of it."""

    def __init__(self):
        self.now = T0
        self.writer: RingWriter | None = None
        self.frames: list[tuple[int, int, int]] = []  # (t_stored, frame_id, t_capture), in order

    def frame(self, frame_id: int, t_capture: int, t_stored: int) -> None:
        self.frames.append((t_stored, frame_id, t_capture))

    def run_until(self, t: int) -> None:
        """Move the clock to ``t``, storing each frame due by then at its own moment."""
        while self.frames and self.frames[0][0] <= t:
            t_stored, frame_id, t_capture = self.frames.pop(0)
            self.now = t_stored
            self.writer.write(np.zeros(self.writer.layout.shape, np.uint8), frame_id, t_capture)
        self.now = t

    def sleep(self, seconds: float) -> None:
        self.run_until(self.now + max(1, int(seconds * 1e9)))


@pytest.fixture
def scripted(monkeypatch):
    """(script, reads): a ring of camera ``a`` written by the script, and a LocalReads over it,
    both on the script's clock."""
    service = f"lwv{os.getpid()}"
    script = Script()
    monkeypatch.setattr(timebase, "now", lambda: script.now)  # the writer's t_stored, liveness checks
    script.writer = writer = RingWriter(service, "a", FrameLayout(8, 32), 8, nominal_period_ns=PERIOD)
    status = {
        "service": service,
        "cameras": {"a": {"kind": "synthetic"}},
        "boot_id": boot_id(),
        "clock": "monotonic",
        "time_namespace": time_namespace(),
    }
    reads = LocalReads(status)
    reads.now = lambda: script.now
    monkeypatch.setattr(localreads, "time", types.SimpleNamespace(sleep=script.sleep))
    try:
        yield script, reads
    finally:
        reads.close()
        writer.close()
        naming.remove_leftovers(service)


def test_a_wait_after_a_frame_stored_late_ends_when_the_next_frame_is_stored(scripted):
    """A worker held up by the machine stores a frame 40 ms after its capture; the camera's
    next frame is still captured and stored on time. The wait for that next frame must end
    when it is stored. It once slept until the late frame's storage plus a period (less a
    1.5 ms margin): 38 ms past the frame it waited for, the 40-51 ms local waits of the demo."""
    script, reads = scripted
    for k in range(3):
        script.frame(k, T0 + k * PERIOD, T0 + k * PERIOD + MS // 2)
    script.frame(3, T0 + 3 * PERIOD, T0 + 3 * PERIOD + 40 * MS)  # stored late
    script.frame(4, T0 + 4 * PERIOD, T0 + 4 * PERIOD + MS // 2)  # on time
    script.frame(5, T0 + 5 * PERIOD, T0 + 5 * PERIOD + MS // 2)
    script.run_until(T0 + 3 * PERIOD + 40 * MS + 100_000)  # the late frame is the newest

    header, images, _ = reads.answer("image", {"camera": "a", "at": T0 + 4 * PERIOD}, script.now + 1_000 * MS)

    (frame,) = header["frames"]
    assert frame["frame_id"] == 4  # the frame nearest t*, which it had to wait for
    late_ms = (header["timing"]["copied"] - frame["t_stored"]) / MS
    assert late_ms <= 0.2, f"the wait ended {late_ms:.1f} ms after the frame it waited for was stored"


def test_a_wait_for_a_frame_on_time_sleeps_until_just_before_it(scripted):
    """The nap still saves the CPU: with frames on time the client sleeps until the margin
    before the next frame is due, then polls only for that margin."""
    script, reads = scripted
    for k in range(6):
        script.frame(k, T0 + k * PERIOD, T0 + k * PERIOD + MS // 2)
    script.run_until(T0 + 3 * PERIOD + MS)
    naps = []
    sleep = script.sleep

    def counted(seconds):
        naps.append(seconds)
        sleep(seconds)

    localreads.time.sleep = counted
    header, _, _ = reads.answer("image", {"camera": "a", "at": T0 + 4 * PERIOD}, script.now + 1_000 * MS)

    assert header["frames"][0]["frame_id"] == 4
    assert (header["timing"]["copied"] - header["frames"][0]["t_stored"]) <= localreads.POLL_S * 1e9
    assert naps[0] * 1e9 == pytest.approx(PERIOD - MS - localreads.WAKE_MARGIN_NS + MS // 2, abs=1_000)
    assert len(naps) <= 1 + (localreads.WAKE_MARGIN_NS // (localreads.POLL_S * 1e9)) + 1
