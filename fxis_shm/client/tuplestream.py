"""A stream of joint tuples across several services, made by the caller (``Client([a, b])
.subscribe().tuples(rate_hz)``): at every time t* of a schedule (one every 1/rate, from the
moment the stream starts) a tuple at t*, chosen by the request engine and joint selection
exactly as ``Client([a, b]).tuple(at=t*)`` would choose it.

Each tuple is asked for once its frames can all be stored (t* plus the slowest camera's
period and delay), so the engine rarely waits and the rate is the schedule's. A stream a little
behind (a busy host) catches up, so the long-run rate is the one asked; one further behind than
a second (a stall, a host down), or so far behind that the times it missed are no longer held
(the shortest ring's span), gives up those times rather than send a burst or fail. A
tuple that cannot be made (a service down) is a message with its error, as ``message.tuple``
raises it. The stream runs in a thread with clients of its own: the caller's
sockets are not shared, and a subscriber slow to read holds up no one (its queue keeps the
newest messages; ``seq`` gaps say what it missed).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

import zmq

from fxis_shm.client.jointrequests import JointRequests
from fxis_shm.client.pubsub import Message
from fxis_shm.client.requestoptions import RequestOptions
from fxis_shm.client.single import SingleClient
from fxis_shm.core.decimation import every_frame
from fxis_shm.errors import Code, FxisError, RequestTimeout
from fxis_shm.wire import protocol
from fxis_shm.wire.headers import ReplyHeader
from fxis_shm.wire.protocol import StreamTopic

LAG_MARGIN_NS = 2_000_000  # after t* + period + delay, the frames around t* are stored
FIRST_PERIOD_NS = 100_000_000  # the schedule's interval until the cameras' periods are known
GIVE_UP_NS = 1_000_000_000  # times further behind than this are given up; nearer ones are caught up


def catch_up_limit_ns(interval_ns: int, lag_ns: int, held_ns: int | None) -> int:
    """How far behind its schedule (past t* plus ``lag_ns``) a stream may fall and still catch
    up: a second at most, and not so far that a time it would ask for is older than what every
    camera holds (``held_ns``, the shortest ring's span; None: not known yet): the time asked
    next is then at most ``lag_ns`` plus one interval old. Never less than one interval."""
    limit = GIVE_UP_NS if held_ns is None else min(GIVE_UP_NS, held_ns - lag_ns - interval_ns)
    return max(interval_ns, limit)


def next_time(t_star: int, interval_ns: int, lag_ns: int, held_ns: int | None, now: int) -> int:
    """The schedule's t* after ``t_star``: one interval on, or, for a stream further behind at
    ``now`` than catch_up_limit_ns, the times it missed given up (whole intervals: the grid stays)."""
    t_next = t_star + interval_ns
    late = now - lag_ns - t_next
    if late > catch_up_limit_ns(interval_ns, lag_ns, held_ns):
        t_next += math.floor(late / interval_ns) * interval_ns
    return t_next


class TupleStream:
    """Joint tuples of every camera of ``endpoints`` (camera -> endpoint in ``owner``), handed
    to ``deliver`` as Messages on ``topic``."""

    def __init__(
        self,
        topic: str,
        stream: StreamTopic,
        owner: dict[str, str],
        options: dict[str, Any],  # each service's SingleClient's
        deliver: Callable[[Message], None],
        bell: str,
        partial: bool = False,
    ):
        """``deliver`` keeps each message; a byte sent to ``bell`` (an inproc address) then
        wakes the subscriber's poll."""
        self.topic, self.stream, self.partial, self.deliver, self.bell = topic, stream, partial, deliver, bell
        self._clients = {e: SingleClient(e, **options) for e in dict.fromkeys(owner.values())}
        try:
            first = next(iter(self._clients.values()))
            self._clock = first.clock
            self._requests = JointRequests({c: self._clients[e] for c, e in owner.items()}, self._clock, first.timeout)
        except BaseException:
            self._close_clients()
            raise
        self.seq = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"fxis-tuples-{topic}", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self._requests.close()
        self._close_clients()

    def _close_clients(self) -> None:
        for client in self._clients.values():
            client.close()

    # ---- the schedule ----

    def _interval_ns(self) -> int:
        """1/rate; without a rate (or above the cameras' rate), the slowest camera's period."""
        slowest = max((c.period_ns for c in self._requests.cameras.values()), default=0)
        if every_frame(self.stream.rate_hz, slowest):
            return slowest or FIRST_PERIOD_NS
        assert self.stream.rate_hz is not None
        return round(1e9 / self.stream.rate_hz)

    def _lag_ns(self) -> int:
        """How long after t* every camera's frames around it are stored."""
        cams = self._requests.cameras.values()
        return max((c.period_ns + c.state(c.snapshot()).delay_ns for c in cams), default=0) + LAG_MARGIN_NS

    def _run(self) -> None:
        bell: zmq.Socket[bytes] = zmq.Context.instance().socket(zmq.PUSH)  # used by this thread only
        bell.setsockopt(zmq.LINGER, 0)
        bell.setsockopt(zmq.SNDHWM, 1)  # one ring wakes the subscriber, however many messages wait
        bell.connect(self.bell)
        try:
            self._schedule(bell)
        finally:
            bell.close()

    def _schedule(self, bell: zmq.Socket[bytes]) -> None:
        t_star = self._clock()
        while not self._stop.is_set():
            message = self._tuple_at(t_star)
            if self._stop.is_set():
                return
            self.deliver(message)
            try:
                bell.send(b"", zmq.NOBLOCK)
            except zmq.Again:
                pass  # it rings already
            lag = self._lag_ns()
            t_star = next_time(t_star, self._interval_ns(), lag, self._held_ns(), self._clock())
            self._stop.wait(max(0, t_star + lag - self._clock()) / 1e9)

    def _held_ns(self) -> int | None:
        """The span of frames every camera holds (the shortest ring's, as last described)."""
        timelines = [c.snapshot().timeline for c in self._requests.cameras.values()]
        return min((t.at(len(t) - 1) - t.at(0) for t in timelines if len(t) > 1), default=None)

    def _tuple_at(self, t_star: int) -> Message:
        self.seq += 1
        # a message as the service's own streams publish it (protocol.encode_reply: v, id None, ok)
        body: ReplyHeader = {"v": protocol.VERSION, "id": None, "ok": True, "stream": self.topic[:-1], "seq": self.seq}
        if self.seq == 1 and self.stream.rate_hz:
            body["rate"] = {"asked_hz": self.stream.rate_hz}
        try:
            options = RequestOptions(encoding=self.stream.encoding, quality=self.stream.quality)
            header, images, _ = self._requests.answer("tuple", options, at=t_star, partial=self.partial or None)
        except FxisError as exc:
            code = Code.TIMEOUT if isinstance(exc, RequestTimeout) else getattr(exc, "code", Code.INTERNAL)
            message = str(exc).removeprefix(f"{code}: ")
            return Message(self.topic, {**body, "ok": False, "error": {"code": code, "message": message}}, [])
        return Message(self.topic, {**header, **body}, images)
