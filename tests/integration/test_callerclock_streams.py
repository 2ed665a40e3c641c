"""Streams and request events in the caller's clock, on a host whose clock is 1000 s ahead:
``Client.subscribe()`` and ``Client.events()`` are bound to the client's clock estimate, so a
stream and a request give the same time for the same frame, and an event's ``at`` asks for
the caller's moment (issue 21, item 1)."""

from __future__ import annotations

import time

import pytest

from fxis_shm import InvalidArgument, Subscriber, handshake, read_stamp

from ..conftest import wait_until
from .conftest import SMALL
from .test_hosts import FPS, MARGIN_NS, PERIOD_NS, _client, _estimated, _true_caller_time

pytestmark = pytest.mark.integration

# 10 s of frames: each test asks for a moment it saw or chose earlier, and on a loaded machine its
# process may stall a second before the ring is read (the default 20 slots hold 1 s at 20 fps)
HELD = ("--history", "10")


def test_a_stream_and_a_request_give_the_same_time_for_the_same_frame(emulated_hosts):
    host = emulated_hosts.host(clock_offset_s=1000)
    svc = host.service("--camera", f"cam=synthetic:fps={FPS},{SMALL}", *HELD)
    with _client(emulated_hosts, svc.endpoint) as client:
        estimate = _estimated(client, svc.endpoint)
        with client.subscribe(timeout=10) as sub:
            sub.frames("cam")
            streamed = wait_until(lambda: sub.receive().frames[0], timeout=20, what="a streamed frame")
        asked = client.image("cam", at=streamed.t_capture, wait="none")
    assert read_stamp(streamed.image) == streamed.frame_id == asked.frame_id
    bound = estimate.uncertainty_ns + MARGIN_NS
    assert abs(streamed.t_capture - asked.t_capture) <= bound
    assert abs(streamed.t_capture - _true_caller_time(streamed, host)) <= bound  # ours, not the host's
    assert streamed.service_t_capture - streamed.t_capture > 999 * 10**9  # the host's own, kept


def test_an_event_request_at_a_moment_of_the_callers_clock_answers_the_frames_nearest_it(emulated_hosts):
    host = emulated_hosts.host(clock_offset_s=1000)
    svc = host.service("--camera", f"cam=synthetic:fps={FPS},{SMALL}", *HELD)
    with _client(emulated_hosts, svc.endpoint) as client:
        estimate = _estimated(client, svc.endpoint)
        with client.events() as events, client.subscribe(timeout=10) as answers:
            answers.topic("robot1")
            handshake(events, answers, "robot1", timeout=20)
            deep = 0.3 * FPS + 3  # frames from before t*: a service just started may hold fewer
            wait_until(lambda: client.status()["cameras"]["cam"]["frames_stored"] >= deep, what="300 ms of frames")
            t_star = time.monotonic_ns() - 300_000_000  # 300 ms ago, on our clock
            events.request("image", "robot1", camera="cam", at=t_star)
            frame = answers.receive().frames[0]
    bound = estimate.uncertainty_ns + MARGIN_NS
    assert abs(frame.t_capture - t_star) <= PERIOD_NS // 2 + bound
    assert abs(_true_caller_time(frame, host) - t_star) <= PERIOD_NS // 2 + bound


def test_a_clock_without_the_service_to_estimate_it_from_is_refused():
    with pytest.raises(InvalidArgument, match="service's request endpoint"):
        Subscriber("tcp://127.0.0.1:9", clock="realtime")
