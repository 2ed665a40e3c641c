"""GigE Vision 2.0 action commands on GVCP: ACTION_CMD (immediate or scheduled) and its
ACTION_ACK, as bytes. Pure: no sockets here (fxis_shm/client/actions.py sends them).

Layout (big-endian, docs/sync.md cites where it comes from):

    command header  key 0x42 | flags | command 0x0100 | length | req_id     (8 bytes)
    ACTION_CMD      device_key | group_key | group_mask [| action_time u64] (12 or 20 bytes)
    ack header      status | answer 0x0101 | length 0 | ack_id             (8 bytes)

Flags: bit 0x01 asks for an acknowledge (common to every command); 0x80 on ACTION_CMD says
the 64-bit action_time follows (a scheduled action, GigE Vision 2.0).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

GVCP_PORT = 3956  # IANA's port for GVCP
KEY = 0x42  # the first byte of every GVCP command
FLAG_ACK_REQUIRED = 0x01
FLAG_SCHEDULED = 0x80  # "action_time present"
ACTION_CMD = 0x0100
ACTION_ACK = 0x0101

# The statuses an ACTION_ACK can carry, with what each means for the sender.
STATUS_SUCCESS = 0x0000
STATUS_NOT_IMPLEMENTED = 0x8001  # no (scheduled) action commands on this device
STATUS_INVALID_PARAMETER = 0x8002
STATUS_ACCESS_DENIED = 0x8006
STATUS_BUSY = 0x8007
STATUS_INVALID_HEADER = 0x800E
STATUS_NO_REF_TIME = 0x8013  # scheduled, but the device clock is not locked to a master (PTP)
STATUS_OVERFLOW = 0x8015  # the device's queue of scheduled actions is full
STATUS_ACTION_LATE = 0x8016  # action_time is already past on the device's clock
STATUS_ERROR = 0x8FFF

STATUS_NAMES = {
    STATUS_SUCCESS: "GEV_STATUS_SUCCESS",
    STATUS_NOT_IMPLEMENTED: "GEV_STATUS_NOT_IMPLEMENTED",
    STATUS_INVALID_PARAMETER: "GEV_STATUS_INVALID_PARAMETER",
    STATUS_ACCESS_DENIED: "GEV_STATUS_ACCESS_DENIED",
    STATUS_BUSY: "GEV_STATUS_BUSY",
    STATUS_INVALID_HEADER: "GEV_STATUS_INVALID_HEADER",
    STATUS_NO_REF_TIME: "GEV_STATUS_NO_REF_TIME",
    STATUS_OVERFLOW: "GEV_STATUS_OVERFLOW",
    STATUS_ACTION_LATE: "GEV_STATUS_ACTION_LATE",
    STATUS_ERROR: "GEV_STATUS_ERROR",
}

STATUS_MEANINGS = {
    STATUS_NOT_IMPLEMENTED: "the device does not implement (scheduled) action commands",
    STATUS_INVALID_PARAMETER: "the device refused a parameter of the command",
    STATUS_ACCESS_DENIED: "the device refused the command (access denied)",
    STATUS_BUSY: "the device is busy",
    STATUS_INVALID_HEADER: "the device found the command's header invalid",
    STATUS_NO_REF_TIME: "the device has no reference time: its clock is not locked to a PTP master",
    STATUS_OVERFLOW: "the device's queue of scheduled actions is full",
    STATUS_ACTION_LATE: "the action time is already past on the device's clock",
    STATUS_ERROR: "the device reports an unspecified error",
}

_HEADER = struct.Struct(">BBHHH")  # key, flags, command, length, req_id
_ACK_HEADER = struct.Struct(">HHHH")  # status, answer, length, ack_id
_KEYS = struct.Struct(">III")  # device_key, group_key, group_mask
_TIME = struct.Struct(">Q")
_U32, _U64 = 0xFFFFFFFF, 0xFFFFFFFFFFFFFFFF


class GvcpFormatError(ValueError):
    """Bytes that are not the packet they claim to be."""


def status_text(status: int) -> str:
    """``GEV_STATUS_ACTION_LATE (0x8016): the action time is already past ...``."""
    name = STATUS_NAMES.get(status, "unknown status")
    meaning = STATUS_MEANINGS.get(status)
    return f"{name} (0x{status:04X})" + (f": {meaning}" if meaning else "")


@dataclass(frozen=True)
class ActionCommand:
    """One ACTION_CMD. ``action_time`` (device clock ticks: ns under PTP) makes it scheduled;
    None makes it immediate."""

    device_key: int
    group_key: int
    group_mask: int
    req_id: int
    action_time: int | None = None
    ack_required: bool = True

    def __post_init__(self) -> None:
        for name in ("device_key", "group_key", "group_mask"):
            if not 0 <= getattr(self, name) <= _U32:
                raise ValueError(f"{name} must fit in 32 bits, not {getattr(self, name)}")
        if not 1 <= self.req_id <= 0xFFFF:  # 0 is reserved: a req_id is never 0
            raise ValueError(f"req_id must be 1..65535, not {self.req_id}")
        if self.action_time is not None and not 0 <= self.action_time <= _U64:
            raise ValueError(f"action_time must fit in 64 bits, not {self.action_time}")

    @property
    def scheduled(self) -> bool:
        return self.action_time is not None

    def encode(self) -> bytes:
        flags = (FLAG_ACK_REQUIRED if self.ack_required else 0) | (FLAG_SCHEDULED if self.scheduled else 0)
        payload = _KEYS.pack(self.device_key, self.group_key, self.group_mask)
        if self.action_time is not None:
            payload += _TIME.pack(self.action_time)
        return _HEADER.pack(KEY, flags, ACTION_CMD, len(payload), self.req_id) + payload

    @classmethod
    def decode(cls, packet: bytes) -> ActionCommand:
        if len(packet) < _HEADER.size + _KEYS.size:
            raise GvcpFormatError(f"an ACTION_CMD has at least 20 bytes, not {len(packet)}")
        key, flags, command, length, req_id = _HEADER.unpack_from(packet)
        if key != KEY or command != ACTION_CMD:
            raise GvcpFormatError(f"not an ACTION_CMD: key 0x{key:02X}, command 0x{command:04X}")
        scheduled = bool(flags & FLAG_SCHEDULED)
        expected = _KEYS.size + (_TIME.size if scheduled else 0)
        if length != expected or len(packet) < _HEADER.size + expected:
            raise GvcpFormatError(
                f"ACTION_CMD {'with' if scheduled else 'without'} action_time has a {expected}-byte payload; "
                f"the header says {length}, the packet has {len(packet) - _HEADER.size}"
            )
        keys = _KEYS.unpack_from(packet, _HEADER.size)
        time = _TIME.unpack_from(packet, _HEADER.size + _KEYS.size)[0] if scheduled else None
        if req_id == 0:
            raise GvcpFormatError("req_id 0 is reserved")
        device_key, group_key, group_mask = keys
        return cls(
            device_key,
            group_key,
            group_mask,
            req_id=req_id,
            action_time=time,
            ack_required=bool(flags & FLAG_ACK_REQUIRED),
        )


@dataclass(frozen=True)
class ActionAck:
    """One ACTION_ACK: the status of the command whose req_id is ``ack_id``; no payload."""

    status: int
    ack_id: int

    @property
    def ok(self) -> bool:
        return self.status == STATUS_SUCCESS

    def encode(self) -> bytes:
        return _ACK_HEADER.pack(self.status, ACTION_ACK, 0, self.ack_id)

    @classmethod
    def decode(cls, packet: bytes) -> ActionAck:
        if len(packet) < _ACK_HEADER.size:
            raise GvcpFormatError(f"a GVCP acknowledge has at least 8 bytes, not {len(packet)}")
        status, answer, _length, ack_id = _ACK_HEADER.unpack_from(packet)
        if answer != ACTION_ACK:
            raise GvcpFormatError(f"not an ACTION_ACK: answer 0x{answer:04X}")
        return cls(status, ack_id)
