"""The ring segment's header and slot table as bytes: the header's fields (``HEADER``), where
the ordered words and a slot's ``seq`` are, how a segment is sized, and the constants every
reader and the writer agree on (fxis_shm.shm.ring reads and writes through them; the C readers,
fxis_shm/shm/seqlock.h, know the slot record's layout)."""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from fxis_shm.core.snapshot import SLOT

if TYPE_CHECKING:
    from typing_extensions import Buffer

MAGIC = b"FXISRNG1"
LAYOUT_VERSION = 3  # 3: the slot record holds t_target and capture (64 bytes)
HEADER_BYTES = 1024
PAGE = 4096
STATE_INIT, STATE_LIVE, STATE_RETIRED = 0, 1, 2
FLAG_TRIGGERED = 1  # the camera captures when triggered (trigger=software), not free-running

HEADER = np.dtype(
    [
        ("magic", "S8"),
        ("version", "<u4"),
        ("state", "<u4"),
        ("flags", "<u4"),
        ("_pad", "<u4"),
        ("height", "<u4"),
        ("width", "<u4"),
        ("channels", "<u4"),
        ("slots", "<u4"),
        ("dtype", "S8"),
        ("slot_stride", "<u8"),
        ("data_offset", "<u8"),
        ("generation", "<u8"),
        ("writer_pid", "<u8"),
        ("write_count", "<u8"),
        ("instance", "<u8"),  # random, drawn when the segment is created: names this very segment
        ("heartbeat_ns", "<i8"),
        ("generation_started_ns", "<i8"),
        ("period_ns", "<i8"),
        ("nominal_period_ns", "<i8"),
        ("delay_ns", "<i8"),
        ("frames_captured", "<u8"),
        ("frames_dropped", "<u8"),
        ("hook_errors", "<u8"),
        ("status_text", "S256"),
        # triggers for a moment (workers/triggers.py): the learned latency trigger -> t_capture and
        # its samples, the frames captured for a trigger_at or on the lockstep grid, the triggers
        # that got no frame; the grid (mHz, 0: none) and the lockstep residuals' p50 and p99
        ("trigger_latency_ns", "<i8"),
        ("trigger_samples", "<u8"),
        ("frames_scheduled", "<u8"),
        ("frames_lockstep", "<u8"),
        ("triggers_missed", "<u8"),
        ("lockstep_mhz", "<u8"),
        ("lockstep_phase_ns", "<i8"),
        ("residual_p50_ns", "<i8"),
        ("residual_p99_ns", "<i8"),
        ("timer_late_p50_ns", "<i8"),  # how late the worker's timer fired (its jitter), p50 and p99
        ("timer_late_p99_ns", "<i8"),
        ("lockstep_clock", "<u8"),  # the grid's clock: an index of fxis_shm.core.schedule.GRID_CLOCKS
    ]
)
assert HEADER.names is not None and HEADER.fields is not None  # (a structured dtype has both)
# each field's (dtype, byte offset), as numpy's fields give them
FIELDS: dict[str, tuple[np.dtype[np.generic], int]] = {name: (f[0], f[1]) for name, f in HEADER.fields.items()}
SYNC_FIELDS = HEADER.names[HEADER.names.index("trigger_latency_ns") :]
assert HEADER.itemsize <= HEADER_BYTES and SLOT.itemsize == 64
WRITE_COUNT_AT = FIELDS["write_count"][1]  # byte offsets of the ordered words
# the header's numbers, read in place (a numpy field read costs ten times as much)
_STRUCTS = {"<u4": "<I", "<u8": "<Q", "<i8": "<q"}
NUMBERS = {
    name: (struct.Struct(_STRUCTS[dtype.str]).unpack_from, offset)
    for name, (dtype, offset) in FIELDS.items()
    if dtype.str in _STRUCTS
}


def _gather(fields: list[str]) -> Callable[[Buffer], tuple[int, ...]]:
    """One unpack of header ``fields`` (in order of offset), in place, skipping the bytes between."""
    start = at = FIELDS[fields[0]][1]
    fmt = "<"
    for name in fields:
        dtype, offset = FIELDS[name]
        fmt += f"{offset - at}x{_STRUCTS[dtype.str][1:]}"
        at = offset + dtype.itemsize
    unpack = struct.Struct(fmt).unpack_from
    return lambda buffer: unpack(buffer, start)


LIVENESS = _gather(["state", "writer_pid", "write_count", "heartbeat_ns"])
TIMING = _gather(["period_ns", "delay_ns"])


def seq_at(slot: int) -> int:
    return HEADER_BYTES + slot * SLOT.itemsize  # seq is a slot record's first field


def align_to_page(n: int, to: int = PAGE) -> int:
    return (n + to - 1) // to * to
