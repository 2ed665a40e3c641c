"""Send GigE Vision action commands (fxis_shm/wire/gvcp_action.py) over UDP and collect each
device's ACTION_ACK: ``ActionSender(...).fire(["10.0.0.5", ...], action_time=T)``.

GVCP is request/acknowledge over UDP: a command without an answer within the timeout is sent
again, unchanged (same req_id, so a device that did get it can tell the copy apart), up to
``retries`` times, as Aravis does for its own GVCP commands. One packet may go to a broadcast
address (``via=``); the devices listed are then the ones whose ACKs are awaited.
"""

from __future__ import annotations

import itertools
import socket
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from fxis_shm.client.sockets import Closable
from fxis_shm.core.ptp import PtpState, require_locked
from fxis_shm.wire.gvcp_action import GVCP_PORT, STATUS_SUCCESS, ActionAck, ActionCommand, GvcpFormatError, status_text

DEFAULT_TIMEOUT_S = 0.2  # per attempt; shorter than Aravis' 500 ms: an action must land before T
DEFAULT_RETRIES = 3


@dataclass(frozen=True)
class ActionOutcome:
    """What one device answered: its ACK status, or None when it never answered."""

    device: str
    status: int | None
    attempts: int

    @property
    def ok(self) -> bool:
        return self.status == STATUS_SUCCESS

    @property
    def error(self) -> str | None:
        """One line saying what went wrong, or None."""
        if self.status is None:
            return f"{self.device}: no ACTION_ACK after {self.attempts} attempt(s)"
        return None if self.ok else f"{self.device}: {status_text(self.status)}"


class ActionFailed(RuntimeError):
    """Some device did not acknowledge the action with success; ``outcomes`` has them all."""

    def __init__(self, outcomes: dict[str, ActionOutcome]):
        self.outcomes = outcomes
        super().__init__("; ".join(o.error for o in outcomes.values() if o.error))


def check(outcomes: dict[str, ActionOutcome]) -> dict[str, ActionOutcome]:
    """``outcomes``, or ActionFailed naming every device that failed and why."""
    if any(not o.ok for o in outcomes.values()):
        raise ActionFailed(outcomes)
    return outcomes


class ActionSender(Closable):
    """Action commands of one (device_key, group_key, group_mask), from one UDP socket."""

    def __init__(
        self,
        device_key: int,
        group_key: int,
        group_mask: int,
        *,
        port: int = GVCP_PORT,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        retries: int = DEFAULT_RETRIES,
        bind: str = "0.0.0.0",
    ):
        self.keys = (device_key, group_key, group_mask)
        self.port, self.timeout_s, self.retries = port, timeout_s, retries
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        self._sock.bind((bind, 0))
        self._req_ids = itertools.count(1)

    def close(self) -> None:
        self._sock.close()

    def _next_req_id(self) -> int:
        return next(self._req_ids) % 0xFFFF + 1  # 1..65535: 0 is reserved

    def fire(
        self,
        devices: Iterable[str],
        action_time: int | None = None,
        *,
        via: str | None = None,
        clocks: Mapping[str, PtpState] | None = None,
    ) -> dict[str, ActionOutcome]:
        """Send the action (scheduled at ``action_time`` in the devices' clock ticks, or
        immediate) to each device's address, or once to ``via`` (a broadcast address), and
        return per device what it answered. Never raises for a device's answer: ``check()``.

        ``clocks``: the PTP state of (some of) the devices; a scheduled action is refused
        (ClockNotLocked, nothing sent) if one of them is not locked."""
        devices = list(dict.fromkeys(devices))
        if not devices:
            raise ValueError("an action command needs at least one device address")
        if action_time is not None and clocks:
            require_locked({d: clocks[d] for d in devices if d in clocks})
        command = ActionCommand(*self.keys, req_id=self._next_req_id(), action_time=action_time)
        packet = command.encode()
        answers: dict[str, int] = {}
        attempts = 0
        while attempts <= self.retries and len(answers) < len(devices):
            targets = [via] if via else [d for d in devices if d not in answers]
            for target in targets:
                self._sock.sendto(packet, (target, self.port))
            attempts += 1
            self._collect(command.req_id, devices, answers, time.monotonic() + self.timeout_s)
        return {d: ActionOutcome(d, answers.get(d), attempts) for d in devices}

    def _collect(self, req_id: int, devices: list[str], answers: dict[str, int], deadline: float) -> None:
        """ACKs of ``req_id`` from ``devices`` until all answered or ``deadline``; anything
        else (stale ACKs of an earlier command, strangers, garbage) is ignored."""
        while len(answers) < len(devices):
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return
            self._sock.settimeout(remaining)
            try:
                data, (address, _port) = self._sock.recvfrom(2048)
            except TimeoutError:
                return
            except ConnectionRefusedError:  # an ICMP port-unreachable from an earlier send
                continue
            try:
                ack = ActionAck.decode(data)
            except GvcpFormatError:
                continue
            if ack.ack_id == req_id and address in devices:
                answers.setdefault(address, ack.status)
