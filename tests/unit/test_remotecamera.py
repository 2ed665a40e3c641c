from fxis_shm.core.engine import Reply, RequestEngine
from fxis_shm.core.remotecamera import RemoteCamera
from fxis_shm.wire.protocol import request_of

COLUMNS = ["frame_id", "t_capture", "t_stored", "t_available", "generation"]
MS = 1_000_000


def described(name, offset, first_capture, period=20 * MS, count=10, alive=True):
    rows = [
        [i, first_capture + i * period, first_capture + i * period + 2 * MS, first_capture + i * period + MS, 1]
        for i in range(count)
    ]
    cam = RemoteCamera(name, f"tcp://host-{name}:5555")
    cam.describe(
        {
            "alive": alive,
            "reason": None if alive else "its worker is not running",
            "period_ns": period,
            "delay_ns": 0,
            "slots": 16,
            "triggered": False,
            "frames": rows,
        },
        COLUMNS,
        offset,
    )
    return cam


def test_times_move_into_the_callers_clock():
    cam = described("a", offset=1000 * 10**9, first_capture=1000 * 10**9 + 5 * MS)
    snap = cam.snapshot()
    assert snap.timeline.at(0) == 5 * MS  # the service is 1000 s ahead of the caller
    assert cam.state(snap).newest_stored == 5 * MS + 9 * 20 * MS + 2 * MS
    assert cam.service_row(0)["t_capture"] == 5 * MS  # fetched by the caller's time; the client maps it
    assert cam.next_stored() == cam.state(snap).newest_stored + 20 * MS


def test_one_engine_chooses_across_services_on_mapped_times():
    # Service b's clock is 7 s behind the caller's; its frames lie 3 ms after a's in the caller's clock.
    a = described("a", offset=0, first_capture=100 * MS)
    b = described("b", offset=-7 * 10**9, first_capture=103 * MS - 7 * 10**9)
    engine = RequestEngine({"a": a, "b": b})
    (reply,) = engine.submit(request_of("tuple", id=None, at=155 * MS, wait="none"), 400 * MS, ticket=1)
    assert isinstance(reply, Reply)
    picked = {cam: reply.snapshots[cam].timeline.at(i) for cam, i in reply.plan.picks}
    assert picked == {"a": 160 * MS, "b": 163 * MS}  # the least skewed pair nearest t*
    assert reply.plan.body["skew_ns"] == 3 * MS


def test_an_unreachable_service_makes_its_camera_down_naming_it():
    cam = described("a", offset=0, first_capture=0)
    cam.unreachable("at tcp://host-a:5555 does not answer (timeout)")
    assert "tcp://host-a:5555" in cam.down_reason(0)
    assert described("b", 0, 0, alive=False).down_reason(0) == "its worker is not running"
