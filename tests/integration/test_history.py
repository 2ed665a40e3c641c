"""History sized in seconds: a ring holds the seconds asked for at its camera's rate, the
status says how many it holds, and a history /dev/shm cannot hold is refused before anything
is created."""

from __future__ import annotations

import pytest

from fxis_shm.shm import naming

from ..conftest import fxis, fxis_run_alone, wait_until
from .conftest import SMALL
from .frozen import frozen

pytestmark = pytest.mark.integration


def test_a_ring_holds_the_seconds_asked_for_and_a_request_that_far_back_is_answered(start_service):
    svc = start_service(
        "--camera",
        # buffers=100: a worker held up on a loaded machine stores every frame it missed, late, where
        # the default 12 (240 ms) would lose some, and the frame nearest t* with them
        f"a=synthetic:fps=50,{SMALL},history=1.5,buffers=100",
        "--camera",
        f"b=synthetic:fps=20,{SMALL}",
        "--history",
        "3",
    )
    with svc.client() as client:
        cams = client.status()["cameras"]
        assert (cams["a"]["ring_slots"], cams["b"]["ring_slots"]) == (77, 62)  # 1.5 s x 50, 3 s x 20, + 2 spare
        assert cams["a"]["history_s"] >= 1.49 and cams["b"]["history_s"] >= 2.99
        wait_until(lambda: client.status()["cameras"]["a"]["frames_stored"] >= 77, what="a's ring full")
        # a's worker stopped while its ring is read: t* is 0.1 s inside the ring, which a worker or
        # this process held up between reading the newest frame (or the time) and asking would pass
        with frozen(client, "a"):
            newest = client.latest(["a"])["a"].t_capture
            t_star = newest - 1_400_000_000  # 1.4 s back: 20 slots (the old default) held 0.4 s of a
            frame = client.image("a", at=t_star, wait="none")
        assert abs(frame.t_capture - t_star) <= 10_000_000
    status = fxis("status", "--endpoint", svc.endpoint)
    assert "history_s" in status.stdout


def test_a_history_dev_shm_cannot_hold_is_refused_before_anything_is_created():
    name = "toolong"
    result = fxis_run_alone("--name", name, "--camera", "a=synthetic:fps=30", "--history", "3600")
    assert result.returncode == 2
    line = result.stderr.strip().splitlines()[-1]
    assert "the rings need" in line and "MiB" in line and "/dev/shm has" in line and "--history" in line
    assert naming.leftovers(name) == []


def test_history_must_be_a_positive_number_of_seconds():
    result = fxis_run_alone("--camera", "a=synthetic:history=0")
    assert result.returncode == 2 and "history" in result.stderr and "Traceback" not in result.stderr
    result = fxis_run_alone("--history", "soon")
    assert result.returncode == 2 and "history must be seconds > 0" in result.stderr
