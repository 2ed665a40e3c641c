"""The GigE Vision action-command codec (fxis_shm/wire/gvcp_action.py): round trips, and
golden bytes written from a second reading of the specification (docs/sync.md, sources)."""

import pytest

from fxis_shm.wire import gvcp_action as gvcp

# Golden packets, byte by byte, from two readings other than ours:
# - Wireshark's GVCP dissector (wireshark/wireshark, epan/dissectors/packet-gvcp.c):
#   GVCP_ACTION_CMD 0x0100 / GVCP_ACTION_ACK 0x0101; the key 0x42 at offset 0, flags at
#   offset 1, "scheduledactioncommand = (flags & 0x80)"; dissect_action_cmd reads device key,
#   group key, group mask at payload offsets 0, 4, 8 and the 64-bit action time at 12, big endian;
#   the acknowledge header is status, acknowledge code, length, ack id.
# - a device SDK's "GigE Vision 2.0.03" gvcp_define.h: CMD_MSG_HEADER {u8 key 0x42; u8 flag;
#   u16 command; u16 length; u16 req_id}, GVCP_CMD_FLAG_NEED_ACK 0x01,
#   GVCP_CMD_FLAG_ACTION_TIME 0x80 ("Figure 16-17: ACTION_CMD Message"), ACTION_CMD_MSG
#   {u32 device_key; u32 group_key; u32 group_mask; u32 action_time_high; u32 action_time_low}.
SCHEDULED = bytes.fromhex(
    "42"  # key
    "81"  # flags: 0x80 action_time present | 0x01 acknowledge required
    "0100"  # ACTION_CMD
    "0014"  # length: 20 payload bytes
    "1234"  # req_id
    "11223344"  # device_key
    "00000001"  # group_key
    "ffffffff"  # group_mask
    "0000000100000002"  # action_time = 2**32 + 2 (high word, low word)
)
IMMEDIATE = bytes.fromhex("42 01 0100 000c 0001 11223344 00000001 00000003")  # flags: acknowledge only
ACK_LATE = bytes.fromhex("8016 0101 0000 1234")  # status ACTION_LATE, ACTION_ACK, length 0


def test_a_scheduled_action_command_is_the_golden_packet():
    command = gvcp.ActionCommand(0x11223344, 1, 0xFFFFFFFF, req_id=0x1234, action_time=2**32 + 2)
    assert command.encode() == SCHEDULED
    assert gvcp.ActionCommand.decode(SCHEDULED) == command


def test_an_immediate_action_command_has_no_time_and_no_scheduled_flag():
    command = gvcp.ActionCommand(0x11223344, 1, 3, req_id=1)
    assert command.encode() == IMMEDIATE
    decoded = gvcp.ActionCommand.decode(IMMEDIATE)
    assert decoded == command and not decoded.scheduled


def test_an_action_ack_is_the_golden_packet():
    assert gvcp.ActionAck(gvcp.STATUS_ACTION_LATE, 0x1234).encode() == ACK_LATE
    assert gvcp.ActionAck.decode(ACK_LATE) == gvcp.ActionAck(gvcp.STATUS_ACTION_LATE, 0x1234)


@pytest.mark.parametrize("time", [None, 0, 1, 2**63, 2**64 - 1])
@pytest.mark.parametrize("ack", [True, False])
def test_action_commands_round_trip(time, ack):
    command = gvcp.ActionCommand(2**32 - 1, 0, 0x80000001, req_id=65535, action_time=time, ack_required=ack)
    assert gvcp.ActionCommand.decode(command.encode()) == command


@pytest.mark.parametrize(
    "status, words",
    [
        (gvcp.STATUS_SUCCESS, "GEV_STATUS_SUCCESS (0x0000)"),
        (gvcp.STATUS_ACTION_LATE, "already past"),
        (gvcp.STATUS_NO_REF_TIME, "not locked to a PTP master"),
        (gvcp.STATUS_OVERFLOW, "queue of scheduled actions is full"),
        (0x8ABC, "unknown status (0x8ABC)"),
    ],
)
def test_statuses_read_as_what_they_mean(status, words):
    assert words in gvcp.status_text(status)
    assert gvcp.ActionAck.decode(gvcp.ActionAck(status, 7).encode()).status == status


@pytest.mark.parametrize(
    "packet, words",
    [
        (SCHEDULED[:27], "payload"),  # the time cut short
        (IMMEDIATE[:12], "at least 20 bytes"),
        (b"\x43" + SCHEDULED[1:], "not an ACTION_CMD"),
        (SCHEDULED[:2] + b"\x00\x80" + SCHEDULED[4:], "not an ACTION_CMD"),  # READREG_CMD
        (SCHEDULED[:1] + b"\x01" + SCHEDULED[2:], "payload"),  # 20 bytes, but no scheduled flag
        (IMMEDIATE[:6] + b"\x00\x00" + IMMEDIATE[8:], "req_id 0"),
    ],
)
def test_malformed_commands_are_refused_saying_why(packet, words):
    with pytest.raises(gvcp.GvcpFormatError, match=words):
        gvcp.ActionCommand.decode(packet)


def test_other_acknowledges_are_not_action_acks():
    with pytest.raises(gvcp.GvcpFormatError, match="not an ACTION_ACK"):
        gvcp.ActionAck.decode(bytes.fromhex("0000 0083 0004 0001 00000001"))  # a WRITEREG_ACK
    with pytest.raises(gvcp.GvcpFormatError, match="at least 8 bytes"):
        gvcp.ActionAck.decode(b"\x00\x00\x01\x01")


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(req_id=0), "req_id"),
        (dict(req_id=1, action_time=-1), "action_time"),
        (dict(req_id=1, action_time=2**64), "action_time"),
    ],
)
def test_out_of_range_fields_are_refused(kwargs, words):
    with pytest.raises(ValueError, match=words):
        gvcp.ActionCommand(1, 1, 1, **kwargs)
    with pytest.raises(ValueError, match="group_mask"):
        gvcp.ActionCommand(1, 1, 2**32, req_id=1)
