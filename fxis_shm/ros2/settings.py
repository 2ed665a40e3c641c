"""Camera settings from ROS 2 (issue 36): a node publishes a ``std_msgs/msg/String`` holding JSON on
``NS/settings`` and reads the answer on ``NS/settings/result`` (a String, JSON), since ROS services
do not cross DDS vendors and a topic pair works with any RMW:

    {"id": 7, "camera": "left"}                                     read the settings
    {"id": 8, "camera": "left", "set": {"exposure_us": 2000}}       change them, all or none

The answer repeats ``id`` and ``camera`` and holds the service's own reply (``values``,
``limits``, ``generation``; for a change ``changed`` and ``cost``), or ``error``: a request
that is not such JSON, an unknown camera, a refused value (its limits named), a key the
service's operators' keys do not allow, or any change where the bridge only reads (under
``--curve-operators``, unless ``--ros2-settings allow``: DDS carries no key that could name an
operator; fxis_shm.service.changers). Requests are answered in order, one at a time.
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Callable
from typing import Any

from fxis_shm.errors import FxisError
from fxis_shm.formats import cdr, rosnames
from fxis_shm.ros2.endpoints import STRING, Participant
from fxis_shm.ros2.follow import Counts

log = logging.getLogger("ros2")

READ_ONLY = (
    "this bridge only reads settings: the service names --curve-operators and a DDS node carries no key; "
    "change them over ZeroMQ with an operator's key (fxis set), or start the service with --ros2-settings allow"
)


def parse_request(text: str) -> dict[str, Any]:
    """The request's fields; ValueError saying what is wrong."""
    try:
        request = json.loads(text)
    except ValueError:
        raise ValueError('not JSON: expected {"camera": NAME} or {"camera": NAME, "set": {KEY: VALUE}}') from None
    if not isinstance(request, dict) or not isinstance(request.get("camera"), str):
        raise ValueError('expected a JSON object with "camera": NAME')
    if "set" in request and (not isinstance(request["set"], dict) or not request["set"]):
        raise ValueError('"set" must be an object of at least one KEY: VALUE')
    return request


class SettingsRequests:
    def __init__(
        self,
        participant: Participant,
        namespace: str,
        make_client: Callable,
        stop: threading.Event,
        may_change: bool = True,
    ):
        self.make_client, self.stop, self.may_change = make_client, stop, may_change
        self.counts = Counts()
        self._reader = participant.string_reader(rosnames.topic(namespace, "settings"))
        self._result = participant.writer(rosnames.topic(namespace, "settings", "result"), STRING)
        self.threads = [threading.Thread(target=self._listen, name="ros2-settings", daemon=True)]

    def start(self) -> None:
        for thread in self.threads:
            thread.start()

    def _listen(self) -> None:
        with self.make_client() as client:
            while not self.stop.is_set():
                for text in self._reader.wait(0.1):
                    self._result.write(cdr.encode_string(json.dumps(self.answer(client, text))))

    def answer(self, client: Any, text: str) -> dict[str, Any]:
        try:
            request = parse_request(text)
        except ValueError as exc:
            return self._refused({}, str(exc))
        head = {"id": request.get("id"), "camera": request["camera"]}
        try:
            if "set" in request and not self.may_change:
                return self._refused(head, READ_ONLY)
            if "set" in request:
                reply = client.configure(request["camera"], **request["set"])
            else:
                reply = client.settings(request["camera"])
        except FxisError as exc:
            return self._refused(head, str(exc))
        self.counts.published += 1
        return {**reply, **head}  # the request's own id, never the wire's (a reply header may carry one)

    def _refused(self, head: dict[str, Any], why: str) -> dict[str, Any]:
        self.counts.failed("settings request", ValueError(why))
        return {**head, "error": why}
