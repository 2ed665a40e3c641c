"""GVCP READREG as bytes (fxis_shm/wire/gvcp_register.py): the command's layout and which
datagrams count as its acknowledge."""

import struct

from fxis_shm.wire import gvcp_action, gvcp_register


def ack(status: int, ack_id: int, value: int, answer: int = gvcp_register.READREG_ACK) -> bytes:
    return struct.pack(">HHHHI", status, answer, 4, ack_id, value)


def test_a_readreg_command_is_the_gige_vision_header_then_the_address():
    packet = gvcp_register.encode_readreg(gvcp_register.CCP_REGISTER, 513)
    assert packet == bytes([0x42, 0x01, 0x00, 0x80, 0x00, 0x04, 0x02, 0x01, 0x00, 0x00, 0x0A, 0x00])


def test_the_acknowledge_of_this_request_gives_status_and_value():
    assert gvcp_register.decode_readreg_ack(ack(gvcp_action.STATUS_SUCCESS, 9, 0x2), 9) == (0, 0x2)
    denied = struct.pack(">HHHH", gvcp_action.STATUS_ACCESS_DENIED, gvcp_register.READREG_ACK, 0, 9)
    assert gvcp_register.decode_readreg_ack(denied, 9) == (gvcp_action.STATUS_ACCESS_DENIED, 0)  # no value sent


def test_other_datagrams_are_not_its_acknowledge():
    assert gvcp_register.decode_readreg_ack(ack(0, 8, 1), 9) is None  # another request's
    assert gvcp_register.decode_readreg_ack(ack(0, 9, 1, answer=gvcp_action.ACTION_ACK), 9) is None
    assert gvcp_register.decode_readreg_ack(b"\x00\x00\x00\x81", 9) is None  # short
