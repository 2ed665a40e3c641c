"""Sequence requests at every edge, against a real service."""

import pytest

from fxis_shm import FrameTimeout, ServiceError, read_stamp

from ..conftest import wait_until
from .conftest import SMALL, module_service
from .frozen import frozen, held_by_every_ring_ns, newest_of_all

pytestmark = pytest.mark.integration

PERIOD = 20_000_000  # 50 fps
SLOTS = 20
# buffers=250: a worker held up on a loaded machine stores every frame it missed, late, where the
# default 12 (240 ms) would lose some and break the runs of frame ids these tests assert
CAMERAS = [
    "--camera",
    f"a=synthetic:fps=50,buffers=250,{SMALL}",
    "--camera",
    f"b=synthetic:fps=50,phase_ms=1,buffers=250,{SMALL}",
]


@pytest.fixture(scope="module")
def full_rings():
    """Rings of SLOTS slots that have wrapped around: for the whole ring and more than it holds."""
    for svc in module_service([*CAMERAS, "--slots", str(SLOTS)]):
        with svc.client() as client:
            wait_until(
                lambda: all(c["frames_stored"] > 2 * SLOTS for c in client.status()["cameras"].values()),
                what="the rings to wrap around",
            )
        yield svc


@pytest.fixture(scope="module")
def long_rings():
    """Rings that hold 10 s, for the tests that reach a few periods back from the newest frames:
    held up (a loaded machine) between reading those and asking, a test finds its frames still
    held, where SLOTS slots (380 ms) would have moved on past them."""
    for svc in module_service([*CAMERAS, "--history", "10"]):
        with svc.client() as client:
            wait_until(lambda: held_by_every_ring_ns(client) > 20 * PERIOD, what="400 ms of frames in every ring")
        yield svc


def assert_consecutive(frames):
    ids = [f.frame_id for f in frames]
    assert ids == list(range(ids[0], ids[0] + len(ids)))
    for f in frames:
        assert read_stamp(f.image) == f.frame_id


def test_consecutive_before_after_and_around_one_camera(long_rings):
    with long_rings.client() as client:
        t_star = client.latest(["a"])["a"].t_capture - 5 * PERIOD - PERIOD // 4
        before = client.sequence("consecutive", camera="a", count=4, at=t_star)
        after = client.sequence("consecutive", camera="a", count=4, direction="after", at=t_star)
        around = client.sequence("consecutive", camera="a", count=5, direction="around", at=t_star)
    for seq in (before, after, around):
        assert len(seq) == len(set(f.frame_id for f in seq)) and assert_consecutive(seq) is None
    assert before[-1].t_capture <= t_star < after[0].t_capture
    assert after[0].frame_id == before[-1].frame_id + 1
    assert around[2].frame_id == after[0].frame_id  # t* is P/4 before it: the nearest, in the middle


def test_the_whole_ring_across_the_wrap(full_rings):
    with full_rings.client() as client:
        # a's worker stopped while the ring is read: a frame or two stored between reading the
        # newest and asking for the SLOTS - 1 up to it would overwrite the oldest of them
        with frozen(client, "a"):
            t_star = client.latest(["a"])["a"].t_capture
            frames = client.sequence("consecutive", camera="a", count=SLOTS - 1, at=t_star)
    assert len(frames) == SLOTS - 1
    assert_consecutive(frames)


def test_tuples_follow_the_first_camera(long_rings):
    with long_rings.client() as client:
        # up to a moment both cameras have stored: a worker held up at the moment of the call
        # would have a's frame for b's newest taken as dropped (overdue), and an older one paired
        t_star = newest_of_all(client)
        tuples = client.sequence("consecutive", cameras=["b", "a"], count=6, at=t_star)
    assert [t["b"].frame_id for t in tuples] == list(range(tuples[0]["b"].frame_id, tuples[0]["b"].frame_id + 6))
    assert all(t.skew_ns <= 1_000_000 for t in tuples)
    assert all(t.t_request == t["b"].t_capture for t in tuples)


def test_interval_sequences_backwards_and_forwards(long_rings):
    with long_rings.client() as client:
        # back from b's newest frame too: were b's worker behind a's, b would have no frame near
        # the targets, and each joint tuple would take a frame of a near b's instead
        t_star = newest_of_all(client) - 10 * PERIOD
        back = client.sequence("interval", cameras=["a", "b"], count=4, interval_ms=-40, at=t_star)
        ahead = client.sequence("interval", camera="a", count=3, interval_ms=60, at=t_star)
    assert [t["a"].frame_id - back[0]["a"].frame_id for t in back] == [0, -2, -4, -6]
    assert [f.frame_id - ahead[0].frame_id for f in ahead] == [0, 3, 6]


def test_range(long_rings):
    with long_rings.client() as client:
        end = client.latest(["a"])["a"].t_capture
        frames = client.sequence("range", camera="a", start=end - 5 * PERIOD, end=end)
    assert len(frames) == 6 and frames[-1].t_capture == end
    assert_consecutive(frames)


def test_future_frames_are_waited_for(long_rings):
    with long_rings.client() as client:
        t_star = client.time() + 3 * PERIOD
        # b's 3 frames after t* are waited for until they are stored: up to 5 s, not the default
        # 1, as b's worker may be held up a second on a loaded machine
        frames = client.sequence("consecutive", camera="b", count=3, direction="after", at=t_star, timeout=5.0)
        # A range takes a frame a period overdue as dropped: were a's worker held up then, the
        # tuples would miss some of the window. Its frames are stored first (b's are, by now).
        wait_until(lambda: newest_of_all(client) >= t_star + 2 * PERIOD, what="both cameras' frames of the window")
        tuples = client.sequence("range", cameras=["a", "b"], start=t_star, end=t_star + 2 * PERIOD)
    assert all(f.t_capture >= t_star for f in frames)
    assert_consecutive(frames)
    assert len(tuples) in (2, 3) and all(t.skew_ns <= 1_000_000 for t in tuples)


@pytest.mark.parametrize(
    "kwargs,message",
    [
        (dict(kind="consecutive", camera="a", count=SLOTS), "at most 19 consecutive frames"),
        (dict(kind="interval", camera="a", count=10, interval_ms=-200), "older than the oldest frame"),
        (dict(kind="range", camera="a", start=0, end=10), "older than the oldest frame"),
    ],
)
def test_too_much_history_says_what_is_held(full_rings, kwargs, message):
    with full_rings.client() as client:
        with pytest.raises(ServiceError, match=message) as err:
            client.sequence(**kwargs)
    assert err.value.code == "OUT_OF_RANGE"


def test_too_many_frames_is_refused(start_service, tmp_path):
    svc = start_service(
        "--camera",
        f"a=synthetic:{SMALL}",
        "--camera",
        f"b=synthetic:{SMALL}",
        "--config",
        _config_with(tmp_path, max_sequence_frames=10),
    )
    with svc.client() as client:
        with pytest.raises(ServiceError, match="limit is 10") as err:
            client.sequence("consecutive", count=6)  # 6 tuples of 2 frames
    assert err.value.code == "TOO_LARGE"


def test_partly_filled_and_empty_rings(start_service):
    # "slow" captures its first frame 10 minutes after the service starts: its ring stays empty
    svc = start_service(
        "--camera",
        f"slow=synthetic:fps=0.2,phase_ms=600000,{SMALL}",
        "--camera",
        f"a=synthetic:fps=5,{SMALL}",
        "--slots",
        "30",
    )
    with svc.client() as client:
        with pytest.raises(ServiceError, match="frame") as err:
            client.sequence("consecutive", camera="a", count=25)
        assert err.value.code == "OUT_OF_RANGE"
        assert client.status()["cameras"]["slow"]["frames_stored"] == 0
        with pytest.raises(FrameTimeout, match="did not arrive within 100 ms"):
            client.sequence("consecutive", camera="slow", count=1, timeout=0.1)
        assert client.status()["cameras"]["slow"]["frames_stored"] == 0  # it was empty all along


def _config_with(directory, **settings) -> str:
    path = f"{directory}/{'-'.join(settings)}.toml"
    with open(path, "w") as f:
        f.writelines(f"{k} = {v}\n" for k, v in settings.items())
    return path
