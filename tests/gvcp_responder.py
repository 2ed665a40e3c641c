"""The test double for GigE Vision action commands: a device's ACTION_CMD handling on a UDP
port of its own, with an emulated device clock, that fires a callback (the Aravis fake
camera's TriggerSoftware, tests/aravis_trigger.py) at the scheduled time of that clock.

It answers as the GigE Vision 2.0 specification has a device answer (docs/sync.md):
- a command whose device_key or group_key differs, or whose group_mask shares no bit with
  the device's, is not for this device: dropped without an answer;
- an acknowledge only when the command's flags ask for one;
- scheduled (flag 0x80): GEV_STATUS_NO_REF_TIME while the clock is not locked (PTP),
  GEV_STATUS_ACTION_LATE for a time already past on the device clock (nothing fires),
  GEV_STATUS_OVERFLOW when the queue of scheduled actions is full, else success;
- a retransmission (same sender and req_id) gets the first answer again and fires nothing more.

Standard library only; the clock is CLOCK_REALTIME plus a settable offset (ns).
"""

from __future__ import annotations

import heapq
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from fxis_shm.wire.gvcp_action import (
    GVCP_PORT,
    STATUS_ACTION_LATE,
    STATUS_NO_REF_TIME,
    STATUS_OVERFLOW,
    STATUS_SUCCESS,
    ActionAck,
    ActionCommand,
    GvcpFormatError,
)

SPIN_NS = 2_000_000  # sleep until this close to the action time, then spin: sleep() overshoots


@dataclass(frozen=True)
class Fired:
    """One action carried out: its scheduled time (None: immediate) and the device clock when
    the callback was called and when it returned."""

    action_time: int | None
    called_ns: int
    returned_ns: int


class ActionResponder:
    """``with ActionResponder("127.0.0.35", fire=camera.trigger) as device: ...``"""

    def __init__(
        self,
        address: str,
        *,
        port: int = GVCP_PORT,
        device_key: int = 0x0FEEDBAC,
        group_key: int = 1,
        group_mask: int = 0xFFFFFFFF,
        fire: Callable[[], object] = lambda: None,
        queue_size: int = 4,
        clock_offset_ns: int = 0,
        locked: bool = True,
    ):
        self.keys = (device_key, group_key, group_mask)
        self.fire, self.queue_size = fire, queue_size
        self.clock_offset_ns, self.locked = clock_offset_ns, locked
        self.ignore_next = 0  # drop this many packets unanswered: a lossy link, for retries
        self.received: list[ActionCommand] = []
        self.fired: list[Fired] = []
        self.errors: list[str] = []  # what the fire callback raised
        self._queue: list[tuple[int, int]] = []  # (device time, sequence): heap
        self._answers: dict[tuple[str, int, int], int] = {}  # (host, port, req_id) -> status
        self._cond = threading.Condition()
        self._closed = False
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((address, port))
        self._sock.settimeout(0.05)
        self.address = self._sock.getsockname()
        self._threads = [threading.Thread(target=t, daemon=True) for t in (self._serve, self._run_queue)]

    # ---- the device clock -------------------------------------------------------------------

    def now(self) -> int:
        return time.clock_gettime_ns(time.CLOCK_REALTIME) + self.clock_offset_ns

    # ---- life -----------------------------------------------------------------------------------

    def __enter__(self) -> ActionResponder:
        for thread in self._threads:
            thread.start()
        return self

    def __exit__(self, *exc) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        for thread in self._threads:
            thread.join(5)
        self._sock.close()

    def wait_fired(self, count: int, timeout: float) -> list[Fired]:
        """The first ``count`` actions fired, waiting up to ``timeout`` s for them."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while len(self.fired) < count:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"{len(self.fired)} of {count} actions fired within {timeout} s")
                self._cond.wait(left)
            return self.fired[:count]

    # ---- GVCP -------------------------------------------------------------------------------------

    def _serve(self) -> None:
        while not self._closed:
            try:
                data, sender = self._sock.recvfrom(2048)
            except TimeoutError:
                continue
            except OSError:
                return
            if self.ignore_next > 0:
                self.ignore_next -= 1
                continue
            try:
                command = ActionCommand.decode(data)
            except GvcpFormatError:
                continue  # not an action command: a device answers other commands elsewhere
            self.received.append(command)
            if not self._for_me(command):
                continue
            status = self._accept(command, sender)
            if command.ack_required:
                self._sock.sendto(ActionAck(status, command.req_id).encode(), sender)

    def _for_me(self, command: ActionCommand) -> bool:
        device_key, group_key, group_mask = self.keys
        return (
            command.device_key == device_key and command.group_key == group_key and command.group_mask & group_mask != 0
        )

    def _accept(self, command: ActionCommand, sender: tuple[str, int]) -> int:
        seen = (*sender, command.req_id)
        if seen in self._answers:  # a retransmission: answered, and carried out, once
            return self._answers[seen]
        with self._cond:
            if command.action_time is None:
                status, due = STATUS_SUCCESS, self.now()
            elif not self.locked:
                status, due = STATUS_NO_REF_TIME, None
            elif command.action_time <= self.now():
                status, due = STATUS_ACTION_LATE, None
            elif len(self._queue) >= self.queue_size:
                status, due = STATUS_OVERFLOW, None
            else:
                status, due = STATUS_SUCCESS, command.action_time
            if due is not None:
                heapq.heappush(self._queue, (due, command.action_time is None, len(self._answers)))
                self._cond.notify_all()
        self._answers[seen] = status
        return status

    def _run_queue(self) -> None:
        while True:
            with self._cond:
                while not self._closed and not self._queue:
                    self._cond.wait()
                if self._closed:
                    return
                due = self._queue[0][0]
                left = due - self.now()
                if left > SPIN_NS:  # a new, earlier action may arrive meanwhile: wait, then look again
                    self._cond.wait((left - SPIN_NS) / 1e9)
                    continue
                _, immediate, _ = heapq.heappop(self._queue)
            while self.now() < due:
                pass
            self._carry_out(None if immediate else due)

    def _carry_out(self, action_time: int | None) -> None:
        called = self.now()
        try:
            self.fire()
        except Exception as exc:  # the test reads it; the device stays up
            self.errors.append(f"{type(exc).__name__}: {exc}")
        returned = self.now()
        with self._cond:
            self.fired.append(Fired(action_time, called, returned))
            self._cond.notify_all()
