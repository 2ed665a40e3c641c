"""Same-host reads that wait, fail and follow restarts without the coordinator (issue 12)."""

import os
import random
import signal
import threading
import time

import pytest

from fxis_shm import CameraDown, Client, read_stamp

from ..conftest import run_in_threads, wait_until
from .conftest import SMALL
from .frozen import held_by_every_ring_ns, newest_of_all

pytestmark = pytest.mark.integration


def test_local_and_network_answers_agree_frame_for_frame(start_service):
    # Rings of 10 s (two_cameras' hold 400 ms), and each t* at least a period before the newest
    # frame every camera has stored: the frames nearest it are all stored when the local path
    # answers, and none is overwritten before the network path does. A frame stored in between
    # (a worker held up on a loaded machine catching up) is newer, never nearer.
    svc = start_service(
        "--camera",
        f"cam0=synthetic:fps=50,{SMALL}",
        "--camera",
        f"cam1=synthetic:fps=50,phase_ms=1,{SMALL}",
        "--history",
        "10",
    )
    rng = random.Random(12)
    with Client(svc.endpoint, local="require") as local, Client(svc.endpoint, local="off") as remote:
        wait_until(lambda: held_by_every_ring_ns(local) > 400_000_000, what="400 ms of frames in every ring")
        for _ in range(25):
            newest = newest_of_all(local)
            t_star = newest - rng.randrange(20_000_000, 300_000_000)
            by_ring, by_wire = local.tuple(at=t_star), remote.tuple(at=t_star)
            assert by_ring.path == "local" and by_wire.path == "network"
            assert {c: f.frame_id for c, f in by_ring.items()} == {c: f.frame_id for c, f in by_wire.items()}, t_star
            frame_ring, frame_wire = local.image("cam1", at=t_star), remote.image("cam1", at=t_star)
            assert frame_ring.frame_id == frame_wire.frame_id


# Real time: the frame each waits for comes while cam0's worker gets the CPU; one held up past a
# period and its delay (the parallel pass, 2 cores) has it taken for dropped, and an older answered
@pytest.mark.realtime
def test_many_local_readers_wait_for_the_next_frame_at_once(two_cameras):
    results, errors = [], []

    def reader():
        try:
            with Client(two_cameras.endpoint, local="require", timeout=5.0) as client:
                client.latest()  # learnt the rings
                asked = time.monotonic_ns()
                t_star = asked + 50_000_000  # 2.5 periods ahead: a frame not stored yet
                results.append((asked, t_star, client.image("cam0", at=t_star)))
        except Exception as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    run_in_threads(reader, 12, timeout=30)
    assert not errors, errors[:3]
    assert len(results) == 12
    for asked, t_star, frame in results:
        assert frame.path == "local" and read_stamp(frame.image) == frame.frame_id
        assert frame.t_stored > asked  # waited for a frame stored after the call
        assert abs(frame.t_capture - t_star) <= 10_000_000 + 2_000_000  # the nearest: half a period, and jitter


def _camera_a(svc, client):
    return client.status()["cameras"]["a"]


def test_a_worker_killed_while_a_local_client_waits_gives_camera_down(start_service):
    # 2 fps: a request for a moment 1.5 s ahead waits for several frames.
    svc = start_service("--camera", f"a=synthetic:fps=2,{SMALL}")
    outcome = {}
    with Client(svc.endpoint, local="require", timeout=10.0) as client:
        wait_until(lambda: _camera_a(svc, client).get("frames_stored", 0) >= 1, what="a first frame")
        pid = _camera_a(svc, client)["writer_pid"]
        client.latest()  # learnt the rings
        waiting = threading.Event()

        def wait_for_future_frame():
            waiting.set()
            try:
                outcome["frame"] = client.image("a", at=time.monotonic_ns() + 1_500_000_000)
            except Exception as exc:  # noqa: BLE001 - checked below
                outcome["error"] = exc
            outcome["returned"] = time.monotonic()

        thread = threading.Thread(target=wait_for_future_frame)
        thread.start()
        waiting.wait(5)
        wait_until(lambda: client._reads.engine.pending, what="the request to wait in the client")
        os.kill(pid, signal.SIGKILL)
        killed = time.monotonic()
        thread.join(15)
    assert not thread.is_alive(), "the waiting request hung"
    assert isinstance(outcome.get("error"), CameraDown), outcome
    assert "down" in str(outcome["error"])
    assert outcome["returned"] - killed < 5.0  # the liveness check, not the client's 10 s timeout


def test_a_local_client_follows_a_restarted_worker_by_itself(start_service):
    svc = start_service("--camera", f"a=synthetic:fps=50,{SMALL}")
    with Client(svc.endpoint, local="require", timeout=2.0) as client:
        before = client.image("a")
        assert before.generation == 1 and before.path == "local"
        os.kill(_camera_a(svc, client)["writer_pid"], signal.SIGKILL)
        wait_until(lambda: _camera_a(svc, client)["alive"] is False, what="camera a to show down")
        with pytest.raises(CameraDown):
            client.image("a")

        def restarted_frame():  # until the new worker stored a frame, the newest is the old one's
            try:
                frame = client.image("a")
            except CameraDown:
                return None
            return frame if frame.generation == 2 else None

        after = wait_until(restarted_frame, timeout=20, what="the restarted camera's frames")
    assert after.generation == 2 and after.path == "local"
    assert read_stamp(after.image) == after.frame_id


def test_a_local_client_learns_a_service_restarted_with_more_cameras(start_service):
    first = start_service("--camera", f"a=synthetic:fps=50,{SMALL}")
    with Client(first.endpoint, local="require", timeout=2.0) as client:
        assert client.image("a").path == "local"
        first.stop()
        again = start_service(
            "--camera",
            f"a=synthetic:fps=50,{SMALL}",
            "--camera",
            f"b=synthetic:fps=50,{SMALL}",
            name=first.name,
            endpoint=first.endpoint,
            pub=first.pub,
            events=first.events,
        )
        wait_until(lambda: again.client().status()["cameras"]["b"].get("frames_stored"), what="camera b")
        frame = client.image("b")  # a camera the client had not seen: it learns the rings again
    again.stop()  # before the fixture checks that the first one, of the same name, left nothing
    assert frame.path == "local" and read_stamp(frame.image) == frame.frame_id


def test_a_local_wait_ends_with_the_frame_it_waited_for_not_a_period_later(start_service):
    """A frame may land while the client looks at the rings (the engine's look); the wait after
    that look must still end at once (it once compared write counts read after the look, missed
    that frame and slept a whole period more). Shown without a clock: a software-triggered
    camera stores a frame only when told, so exactly one frame lands between the counts read
    before the look and the wait, and no later one could end the wait instead. How soon a wait
    ends is measured by bench/latency/wake.py."""
    from fxis_shm.client.localreads import LocalReads

    svc = start_service("--camera", f"a=synthetic:trigger=software,{SMALL}")
    with svc.client() as client:
        reads = LocalReads(client.status())
    try:
        ring = reads.cameras["a"].reader
        seen = {"a": ring.field("write_count")}  # read before the look
        reads.cameras["a"].fire_trigger()  # a frame lands during the look
        wait_until(lambda: ring.field("write_count") == seen["a"] + 1, what="the triggered frame stored")
        until = time.monotonic_ns() + 2_000_000_000
        assert reads._wait_for_frames({"a"}, until, seen) == {"a"}, "the frame stored during the look was missed"
        assert seen == {"a": ring.field("write_count")}  # the next wait starts from the counts found
        assert reads._wait_for_frames({"a"}, time.monotonic_ns() + 50_000_000, seen) == set()  # and none since
    finally:
        reads.close()
