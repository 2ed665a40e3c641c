"""CurveZMQ: only clients with allowed keys are served; exposed endpoints need keys."""

import subprocess
import sys
import time

import pytest

from fxis_shm import Client, RequestTimeout
from fxis_shm.client.pubsub import EventPublisher, Subscriber, handshake
from fxis_shm.service.launch import free_tcp_port

from .conftest import SMALL, client_keys
from .test_lifecycle import fxis

pytestmark = pytest.mark.integration


def test_only_allowed_clients_are_served(curve_service):
    svc, folder = curve_service
    alice = Client(svc.endpoint, timeout=15.0, keys=client_keys(folder, "alice"))  # handshakes under load
    mallory = Client(svc.endpoint, timeout=0.5, keys=client_keys(folder, "mallory"))
    stranger = Client(svc.endpoint, timeout=0.5)
    with alice, mallory, stranger:
        assert alice.image("a").camera == "a"
        for intruder in (mallory, stranger):
            for _ in range(3):  # refused, again and again, never hanging (a DEALER without a peer blocks in send)
                with pytest.raises(RequestTimeout):
                    intruder.status()
            assert alice.tuple()["a"].frame_id >= 0  # undisturbed
    with Subscriber(svc.pub, keys=client_keys(folder, "alice")) as sub:
        sub.frames("a")
        assert sub.receive(timeout=15).frames[0].camera == "a"
    with Subscriber(svc.pub, timeout=0.5) as eavesdropper:
        eavesdropper.frames("a")
        with pytest.raises(RequestTimeout):
            eavesdropper.receive()


def test_request_events_are_taken_only_from_allowed_keys(curve_service):
    """The events endpoint is a CurveZMQ server too: a keyless EventPublisher, or one with a key
    the service does not allow, is refused (its events are never answered), while events of an
    allowed key, published in between, are."""
    svc, folder = curve_service
    topic = "cell/answers"
    with (
        Subscriber(svc.pub, keys=client_keys(folder, "alice"), timeout=15) as answers,
        EventPublisher(svc.events, keys=client_keys(folder, "alice")) as alice,
        EventPublisher(svc.events) as stranger,
        EventPublisher(svc.events, keys=client_keys(folder, "mallory")) as mallory,
    ):
        answers.topic(topic)
        handshake(alice, answers, topic, timeout=15)  # handshakes under load
        refused, answered = set(), []
        for _ in range(20):  # a second and more: a keyless PUB would have connected long before
            refused |= {stranger.request("time", topic), mallory.request("time", topic)}
            rid = alice.request("time", topic)
            while True:
                header = answers.receive().header
                assert header.get("id") not in refused, f"an event without an allowed key was answered: {header}"
                if header.get("id") == rid:
                    answered.append(header)
                    break
            time.sleep(0.05)
        with pytest.raises(RequestTimeout):  # and nothing else is on its way
            while True:
                header = answers.receive(timeout=0.5).header
                assert header.get("id") not in refused, f"an event without an allowed key was answered: {header}"
    assert len(answered) == 20 and all(h["ok"] for h in answered)


def test_an_exposed_endpoint_needs_keys():
    port = free_tcp_port()
    result = fxis("run", "--camera", f"a=synthetic:{SMALL}", "--endpoint", f"tcp://0.0.0.0:{port}")
    assert result.returncode == 2
    assert "other hosts" in result.stderr and "curve" in result.stderr


def test_insecure_bind_warns(tmp_path):
    port = free_tcp_port()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "fxis_shm.cli",
            "run",
            "--name",
            f"insecure{port}",
            "--insecure-bind",
            "--camera",
            f"a=synthetic:{SMALL}",
            "--endpoint",
            f"tcp://0.0.0.0:{port}",
            "--pub",
            f"tcp://127.0.0.1:{free_tcp_port()}",
            "--events",
            f"tcp://127.0.0.1:{free_tcp_port()}",
            "--http",
            "off",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        banner = []
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            banner.append(line)
            if "Ctrl-C" in line:
                break
        text = "".join(banner)
        assert "WARNING" in text and f"tcp://0.0.0.0:{port}" in text
    finally:
        proc.terminate()
        proc.wait(15)
