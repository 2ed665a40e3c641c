"""The messages from the coordinator to a camera worker and back (docs/design.md, "Commands to
a camera worker"): one JSON frame each, after the DEALER/ROUTER's empty delimiter.

    command: {"id": n, "cmd": "settings", ...its fields}
    reply:   {"id": n, "ok": true, "result": {...}}  or  {"id": n, "ok": false, "code": C, "error": "..."}

Pure: bytes in, dicts out. ``COMMANDS`` names what a worker understands; a worker of an older
install answers a command it does not know with an error, never by silence.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from fxis_shm.errors import Code, ProtocolError

SETTINGS = "settings"  # read the camera's settings, or change some ("set"), applied between two frames
TRIGGER_AT = "trigger_at"  # {"t": T}: fire the trigger for a capture at T (service clock), at T - latency
# {"hz": HZ, "phase_ns": P, "clock": "realtime"|"tai"}: fire on the grid k/HZ + P of that clock; {"hz": null}: stop
LOCKSTEP = "lockstep"
COMMANDS = (SETTINGS, TRIGGER_AT, LOCKSTEP)
SETTINGS_TIMEOUT_S = 10.0  # a change that restarts a camera's stream may take seconds (GenTL, GigE Vision)
TRIGGER_TIMEOUT_S = 1.0  # trigger_at and lockstep are answered at once, by the worker's command thread


def encode_command(command_id: int, cmd: str, **fields: Any) -> bytes:
    return json.dumps({"id": command_id, "cmd": cmd, **fields}).encode()


def decode_command(frame: bytes) -> dict[str, object]:
    """A command, or ProtocolError saying why it is none (its id kept when readable)."""
    try:
        command = json.loads(bytes(frame))
    except (UnicodeDecodeError, ValueError) as exc:
        raise ProtocolError(f"a worker command is not JSON: {exc}") from None
    if not isinstance(command, dict) or not isinstance(command.get("id"), int):
        raise ProtocolError("a worker command is a JSON object with an integer id")
    if command.get("cmd") not in COMMANDS:
        raise ProtocolError(f"unknown worker command {command.get('cmd')!r}; known: {list(COMMANDS)}", Code.UNKNOWN_OP)
    return command


def encode_result(command_id: int | None, result: Mapping[str, object]) -> bytes:
    return json.dumps({"id": command_id, "ok": True, "result": result}).encode()


def encode_failure(command_id: int | None, code: str, message: str) -> bytes:
    return json.dumps({"id": command_id, "ok": False, "code": code, "error": message}).encode()


def decode_reply(frame: bytes) -> dict[str, object]:
    """A worker's reply: its id, ok, and result or code and error."""
    try:
        reply = json.loads(bytes(frame))
    except (UnicodeDecodeError, ValueError) as exc:
        raise ProtocolError(f"a worker reply is not JSON: {exc}") from None
    if not isinstance(reply, dict) or "ok" not in reply:
        raise ProtocolError("a worker reply is a JSON object with ok")
    return reply
