"""An independent ROS 2-like DDS peer for tests (``python -m tests.dds_peer``, see ``__main__.py``)
and :class:`Peer`, the test's handle on it.

``Peer`` starts the peer process, waits for its ``ready`` line, collects its JSON lines in a
thread, waits on them with deadlines, and ends the process on ``close``/``with`` exit::

    from tests.dds_peer import Peer, domain_id, loopback_config

    domain = domain_id()
    with Peer(domain, {"/cam0/image_raw": "sensor_msgs/msg/Image"}, profile="sensor_data") as peer:
        ...  # start what publishes /cam0/image_raw on `domain`
        image = peer.wait_for_samples("/cam0/image_raw", 1)[0]
        assert image["encoding"] == "mono8" and image["stamp"] == [sec, nanosec]
        peer.publish_header("/frames_at", sec, nanosec, "cam0")

A sample is a dict: ``topic``, ``type``, ``profile``, ``source_timestamp`` (ns), ``stamp``
([sec, nanosec]) and ``frame_id``, then by type: Image ``height``, ``width``, ``encoding``,
``step``, ``is_bigendian``, ``size``, ``sha256``, ``head``/``tail`` (first/last 16 bytes, hex)
and ``rows`` (see :func:`stamp_rows`); CompressedImage ``format``, ``size``, ``sha256``,
``head``, ``tail``; CameraInfo ``height``, ``width``, ``distortion_model``, ``d``, ``k``, ``r``,
``p``, ``binning``, ``roi``; String ``data``. ``with_data=True`` adds ``data`` (base64) to
images.
"""

from __future__ import annotations

import collections
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .config import domain_id as domain_id, loopback_config as loopback_config

ROOT = Path(__file__).resolve().parents[2]  # where `python -m tests.dds_peer` finds the package
# Real ROS 2 nodes (tests/rclpy_peer.py): each distribution's wheels in a virtualenv of their own,
# made by the Makefile (ROS 2's wheels set their library path by re-running Python, so they live
# apart from the project's own venv).
ROS_VENVS = {"kilted": ROOT / ".venv-ros", "jazzy": ROOT / ".venv-ros-jazzy"}
KINDS = ("cyclone", *ROS_VENVS)
READY_TIMEOUT = 30.0  # s from spawn to "ready": an interpreter, cyclonedds, a participant
DEADLINE = 15.0  # s; generous for a loaded box, conditions hold in well under a second here

Event = dict[str, Any]
Subscriptions = Mapping[str, str] | Iterable[tuple[str, str] | tuple[str, str, str]]


def stamp_rows(sample: Event) -> np.ndarray:
    """An Image sample's first 16 bytes (at most) of its first and of its last row, as a (2, 16)
    array: ``fxis_shm.formats.stamp.read_stamp(stamp_rows(sample))`` is the frame id stamped in it."""
    return np.array([np.frombuffer(bytes.fromhex(row), np.uint8) for row in sample["rows"]])


def ros_environment(venv: Path) -> dict[str, str]:
    """What a ROS 2 node from ``venv``'s wheels runs with: ROS 2's default RMW (Fast DDS), the
    venv as its ament prefix, and nothing of ours (no CYCLONEDDS_URI, no library paths)."""
    return {
        "PATH": "/usr/bin:/bin",
        "HOME": os.environ.get("HOME", "/root"),
        "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
        "AMENT_PREFIX_PATH": str(venv),
        "ROS_LOG_DIR": os.path.join(tempfile.gettempdir(), "fxis-ros-logs"),
    }


def peer_command(kind: str, wrapper: list[str]) -> tuple[list[str], dict[str, str]]:
    """The command line and environment of a peer of ``kind``."""
    if kind == "cyclone":
        env = {key: value for key, value in os.environ.items() if key != "CYCLONEDDS_URI"}
        return [*wrapper, sys.executable, "-m", "tests.dds_peer"], env
    venv = ROS_VENVS[kind]
    if not (venv / "bin" / "python").exists():
        raise AssertionError(f"no ROS 2 {kind} venv at {venv}: make test makes it (make ros-venvs)")
    return [*wrapper, str(venv / "bin" / "python"), str(ROOT / "tests" / "rclpy_peer.py")], ros_environment(venv)


class Peer:
    """The peer process, subscribed to ``subscribe`` ({topic: type}, or (topic, type[, profile])
    tuples; ``profile`` for those that name none) and with a Header writer on each of
    ``publish_headers`` (made at start, so its discovery is done by the first publish)."""

    def __init__(
        self,
        domain: int,
        subscribe: Subscriptions = (),
        *,
        profile: str = "default",
        publish_headers: Iterable[str] = (),
        publish_strings: Iterable[str] = (),
        with_data: bool = False,
        lifetime: float = 300.0,
        kind: str = "cyclone",
        wrapper: Iterable[str] = (),
    ) -> None:
        """``kind``: "cyclone" (tests/dds_peer, our own Cyclone participant on loopback) or a ROS 2
        distribution ("kilted", "jazzy": a real rclpy node on Fast DDS, in its default
        configuration, so it must run in a network namespace of the test's: ``wrapper``)."""
        pairs = subscribe.items() if isinstance(subscribe, Mapping) else subscribe
        command, env = peer_command(kind, list(wrapper))
        command += ["--domain", str(domain), "--timeout", str(lifetime)]
        for topic, ros_type, *named in pairs:
            command += ["--sub", f"{topic}:{ros_type}:{named[0] if named else profile}"]
        for topic in publish_headers:
            command += ["--pub-header", topic]
        for topic in publish_strings:  # rclpy peers only
            command += ["--pub-string", topic]
        command += ["--data"] if with_data else []
        self.proc = subprocess.Popen(
            command, cwd=ROOT, env=env, text=True, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
        self._events: list[Event] = []
        self._stderr: collections.deque[str] = collections.deque(maxlen=40)
        self._changed = threading.Condition()
        self._running = True  # until the peer's stdout closes
        self._last_id = 0
        self._threads = [
            threading.Thread(target=self._collect_events, daemon=True),
            threading.Thread(target=self._collect_stderr, daemon=True),
        ]
        for thread in self._threads:
            thread.start()
        try:
            self.wait_for(lambda events: bool(self.of("ready")), READY_TIMEOUT, "the peer's ready line")
        except BaseException:
            self.close()
            raise

    def _collect_events(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                event = json.loads(line)
            except json.JSONDecodeError:
                event = {"event": "garbage", "line": line}
            with self._changed:
                self._events.append(event)
                self._changed.notify_all()
        with self._changed:
            self._running = False
            self._changed.notify_all()

    def _collect_stderr(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self._stderr.append(line)

    @property
    def events(self) -> list[Event]:
        with self._changed:
            return list(self._events)

    def of(self, kind: str, topic: str | None = None, profile: str | None = None) -> list[Event]:
        """The events of one kind ("sample", "matched", ...), of one topic and profile if given."""
        return [
            event
            for event in self.events
            if event["event"] == kind
            and topic in (None, event.get("topic"))
            and profile in (None, event.get("profile"))
        ]

    def samples(self, topic: str | None = None, profile: str | None = None) -> list[Event]:
        return self.of("sample", topic, profile)

    def wait_for(
        self, predicate: Callable[[list[Event]], bool], timeout: float = DEADLINE, what: str = ""
    ) -> list[Event]:
        """Block until ``predicate(events so far)`` holds and return the events; fail the test
        (AssertionError, with the peer's last events and stderr) at the deadline or if the peer ends."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while not predicate(list(self._events)):
                left = deadline - time.monotonic()
                if left <= 0 or not self._running:
                    why = "timed out" if left <= 0 else "the peer ended"
                    if not self._running:
                        self._threads[1].join(timeout=2)  # the peer's last words on stderr
                    raise AssertionError(f"{why} waiting for {what or predicate}: {self._summary()}")
                self._changed.wait(left)
            return list(self._events)

    def wait_for_samples(
        self, topic: str, count: int = 1, *, profile: str | None = None, timeout: float = DEADLINE
    ) -> list[Event]:
        """Block until ``count`` samples of ``topic`` came; all of them so far."""
        self.wait_for(lambda _: len(self.samples(topic, profile)) >= count, timeout, f"{count} samples of {topic}")
        return self.samples(topic, profile)

    def first_sample_of_resent(
        self, topic: str, write: Callable[[], object], *, timeout: float = DEADLINE, every: float = 0.2
    ) -> Event:
        """The first sample of ``topic``, calling ``write()`` again every ``every`` s until one came:
        a best-effort reader gets nothing resent, and on a loaded machine one write can be lost."""
        deadline = time.monotonic() + timeout
        while True:
            write()
            try:
                return self.wait_for_samples(topic, timeout=min(every, deadline - time.monotonic()))[0]
            except AssertionError:
                if time.monotonic() >= deadline:
                    raise

    def wait_matched(
        self, topic: str, count: int = 1, *, profile: str | None = None, timeout: float = DEADLINE
    ) -> Event:
        """Block until the subscription to ``topic`` matches ``count`` writers; its last ``matched``
        event (``writers`` says what discovery told of each).

        Wait for this before writing to a ``sensor_data`` subscription: a writer may see the match
        first, and a best-effort reader drops what arrives before its side matched (a reliable
        reader gets it resent)."""

        def matched() -> list[Event]:
            return self.of("matched", topic, profile)

        self.wait_for(lambda _: bool(matched()) and matched()[-1]["current"] >= count, timeout, f"a match on {topic}")
        return matched()[-1]

    def publish_header(
        self, topic: str, sec: int, nanosec: int, frame_id: str = "", *, min_readers: int = 1, timeout: float = DEADLINE
    ) -> Event:
        """Publish a ``std_msgs/msg/Header`` once ``min_readers`` readers of ``topic`` match;
        its ``published`` event. Fails the test if no reader matches in ``timeout`` s."""
        return self._publish(
            {"cmd": "header", "sec": sec, "nanosec": nanosec, "frame_id": frame_id}, topic, min_readers, timeout
        )

    def publish_string(self, topic: str, data: str, *, min_readers: int = 1, timeout: float = DEADLINE) -> Event:
        """As :meth:`publish_header`, a ``std_msgs/msg/String`` (rclpy peers only)."""
        return self._publish({"cmd": "string", "data": data}, topic, min_readers, timeout)

    def _publish(self, command: dict, topic: str, min_readers: int, timeout: float) -> Event:
        self._last_id += 1
        ident = self._last_id
        command.update(id=ident, topic=topic, min_readers=min_readers, timeout=timeout)
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps(command) + "\n")
        self.proc.stdin.flush()

        def answers() -> list[Event]:
            return [e for e in self.events if e.get("id") == ident and e["event"] in ("published", "error")]

        self.wait_for(lambda _: bool(answers()), timeout + DEADLINE, f"publishing on {topic}")
        answer = answers()[0]
        assert answer["event"] == "published", answer["message"]
        return answer

    def nodes(self, timeout: float = DEADLINE) -> list[tuple[str, str]]:
        """The ROS graph's nodes as this peer sees them, (name, namespace) (rclpy peers only)."""
        self._last_id += 1
        ident = self._last_id
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps({"cmd": "nodes", "id": ident}) + "\n")
        self.proc.stdin.flush()
        events = self.wait_for(lambda events: any(e.get("id") == ident for e in events), timeout, "the node list")
        (answer,) = [e for e in events if e.get("id") == ident]
        assert answer["event"] == "nodes", answer
        return [(name, namespace) for name, namespace in answer["nodes"]]

    def _summary(self) -> str:
        last = [(e["event"], e.get("topic"), e.get("profile"), e.get("stamp")) for e in self._events[-30:]]
        return f"last events {last}; stderr {''.join(self._stderr)[-2000:]!r}"

    def close(self) -> None:
        """End the peer: it leaves when its stdin closes; killed if it has not within 5 s."""
        try:
            if self.proc.stdin:
                self.proc.stdin.close()
            self.proc.wait(timeout=5)
        except (subprocess.TimeoutExpired, OSError):
            pass
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
            for thread in self._threads:
                thread.join(timeout=5)

    def __enter__(self) -> Peer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
