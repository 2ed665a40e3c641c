"""GVCP READREG (one bootstrap register of a GigE Vision device) as bytes, and the control
channel privilege register it is mostly read for. Pure: no sockets here
(workers/backends/aravis_library.py asks with it before opening a camera to list it).

Layout (big-endian, GigE Vision 2.0, the same header as fxis_shm/wire/gvcp_action.py's):

    command header  key 0x42 | flags 0x01 (ack) | command 0x0080 | length 4 | req_id   (8 bytes)
    READREG_CMD     register address u32                                           (4 bytes)
    ack header      status | answer 0x0081 | length 4 | ack_id                      (8 bytes)
    READREG_ACK     register value u32                                             (4 bytes)
"""

from __future__ import annotations

import struct

from .gvcp_action import FLAG_ACK_REQUIRED, KEY

READREG_CMD = 0x0080
READREG_ACK = 0x0081
CCP_REGISTER = 0x0A00  # bootstrap: control channel privilege
CCP_CONTROL_BITS = 0x3  # exclusive | control: some application controls the device
HEARTBEAT_TIMEOUT_REGISTER = 0x0938  # bootstrap: heartbeat timeout (ms); only the controller may write it


def encode_readreg(address: int, req_id: int) -> bytes:
    """A READREG command for one register, asking for an acknowledge."""
    return struct.pack(">BBHHHI", KEY, FLAG_ACK_REQUIRED, READREG_CMD, 4, req_id, address)


def decode_readreg_ack(reply: bytes, req_id: int) -> tuple[int, int] | None:
    """(status, value) of a READREG_ACK to request ``req_id`` (the value means something only
    when the status is GEV_STATUS_SUCCESS); None for any other datagram (another request's
    answer, a short one)."""
    if len(reply) < 8:
        return None
    status, answer, _length, ack_id = struct.unpack(">HHHH", reply[:8])
    if answer != READREG_ACK or ack_id != req_id:
        return None
    value = struct.unpack(">I", reply[8:12])[0] if len(reply) >= 12 else 0
    return status, value
