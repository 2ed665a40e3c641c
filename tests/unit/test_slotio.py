"""The ring reader's seqlock reads (fxis_shm.shm.slotio): the C helper and its Python twin
answer alike on any slot table, whole, torn or half written (hypothesis draws them)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

# _slotio imported directly, so that FXIS_PURE_PYTHON=1 (which makes slotio pick its Python
# twin) still compares the two. Not built is a failure: `make setup` builds it (setup.py).
from fxis_shm.shm import _slotio, slotio

TABLE = 64  # the table's offset in the test buffer (the ring's is 1024)
DATA = 8192  # after the table (the batch test's 84 records)
RECORD = 64  # the ring's slot record (fxis_shm.core.snapshot.SLOT)


def buffer_with(slots: int, records: list[tuple[int, ...]], data: bytes = b"") -> np.ndarray:
    """An 8-byte aligned buffer holding ``records`` (seq and seven fields each) from TABLE on."""
    words = np.zeros((DATA + len(data) + 7) // 8 + 1, dtype=np.uint64)
    raw = words.view(np.uint8)
    table = np.array(records, dtype=np.uint64).reshape(slots, 8) if records else np.zeros((slots, 8), np.uint64)
    raw[TABLE : TABLE + slots * RECORD] = table.view(np.uint8).reshape(-1)
    raw[DATA : DATA + len(data)] = np.frombuffer(data, dtype=np.uint8)
    return raw


@st.composite
def tables(draw):
    """A slot table as a ring shows it after ``count`` writes, each slot whole, being
    written, or holding garbage; and a range of writes to read."""
    slots = draw(st.integers(2, 8))
    count = draw(st.integers(0, 40))
    records = []
    for s in range(slots):
        w = max((v for v in range(count) if v % slots == s), default=s)
        seq = draw(st.sampled_from([2 * w + 2, 2 * w + 1, 2 * w, 0, draw(st.integers(0, 2**64 - 1))]))
        fields = draw(st.lists(st.integers(0, 2**63 - 1), min_size=7, max_size=7))
        records.append((seq, *fields))
    lo = draw(st.integers(0, count))
    hi = draw(st.integers(lo, count + slots))
    return slots, records, lo, hi


@settings(max_examples=300, deadline=None)
@given(tables())
def test_records_are_read_alike(table):
    slots, records, lo, hi = table
    buf = buffer_with(slots, records)
    assert _slotio.records(buf, TABLE, slots, lo, hi) == slotio.py_records(buf, TABLE, slots, lo, hi)


def test_records_keep_only_the_whole_ones():
    slots = 4
    records = [(2 * w + 2, w, 1000 * w, 1000 * w + 5, 1000 * w, 1, 1000 * w - 3, w % 3) for w in range(4, 8)]
    records[2] = (2 * 6 + 1, *records[2][1:])  # write 6 is being written
    buf = buffer_with(slots, records)
    assert [r[0] for r in slotio.records(buf, TABLE, slots, 4, 8)] == [4, 5, 7]
    assert slotio.records(buf, TABLE, slots, 5, 6) == [(5, 5, 5000, 5005, 5000, 1, 4997, 2)]


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**64 - 1), st.booleans(), st.binary(min_size=1, max_size=300))
def test_copies_and_checks_agree(seq, matches, data):
    buf = buffer_with(2, [(seq, *[0] * 7), (0,) * 8], data)
    expected = seq if matches else (seq + 1) % 2**64
    outs = [np.zeros(len(data), np.uint8) for _ in range(2)]
    results = [f(buf, TABLE, expected, DATA, len(data), out) for f, out in zip((_slotio.copy, slotio.py_copy), outs)]
    assert results[0] == results[1] == (0 if matches else 1)
    if matches:
        assert outs[0].tobytes() == outs[1].tobytes() == data
    assert _slotio.holds(buf, TABLE, expected) == slotio.py_holds(buf, TABLE, expected) == matches


def test_the_helper_refuses_what_lies_outside_the_buffer():
    buf = buffer_with(2, [])
    with pytest.raises(ValueError):
        _slotio.records(buf, len(buf) - 8, 2, 0, 1)
    with pytest.raises(ValueError):
        _slotio.copy(buf, TABLE, 2, len(buf) - 4, 8, np.zeros(8, np.uint8))
    with pytest.raises(ValueError, match="target holds"):
        _slotio.copy(buf, TABLE, 0, DATA, 8, np.zeros(4, np.uint8))
    with pytest.raises(ValueError):
        _slotio.holds(buf, TABLE + 3, 0)


@st.composite
def frames(draw):
    """Several frames of one buffer, each whole or overwritten before its copy, of any length."""
    n = draw(st.integers(1, 4))
    seqs = [draw(st.integers(0, 2**63)) for _ in range(n)]
    whole = [draw(st.booleans()) for _ in range(n)]
    lengths = [draw(st.integers(0, 200)) for _ in range(n)]
    return seqs, whole, lengths, draw(st.binary(min_size=sum(lengths), max_size=sum(lengths)))


def jobs_of(buf: np.ndarray, seqs: list[int], whole: list[bool], lengths: list[int]) -> list[tuple]:
    offsets = np.cumsum([0, *lengths])
    return [
        (buf, TABLE + RECORD * k, seq if ok else seq + 1, DATA + int(offsets[k]), n, np.zeros(n, np.uint8))
        for k, (seq, ok, n) in enumerate(zip(seqs, whole, lengths))
    ]


@settings(max_examples=200, deadline=None)
@given(frames())
def test_several_copies_at_once_agree(drawn):
    seqs, whole, lengths, data = drawn
    buf = buffer_with(len(seqs), [(seq, *[0] * 7) for seq in seqs], data)
    jobs = [jobs_of(buf, seqs, whole, lengths) for _ in range(2)]
    results = [_slotio.copies(jobs[0]), slotio.py_copies(jobs[1])]
    first_torn = next((k for k, ok in enumerate(whole) if not ok), None)
    assert results[0] == results[1] == (None if first_torn is None else (first_torn, 1))
    for k in range(len(seqs) if first_torn is None else first_torn):  # copied up to the first torn one
        assert jobs[0][k][5].tobytes() == jobs[1][k][5].tobytes() == buf[jobs[0][k][3] :][: lengths[k]].tobytes()


@pytest.mark.parametrize("torn_at", [None, 0, 63, 64, 83])
def test_more_frames_than_one_c_call_takes_are_copied_in_batches(torn_at):
    """A sequence copies hundreds of frames: the public ``copies`` takes any number (in batches
    of COPIES_AT_ONCE for the C one) and answers as the Python one does."""
    n = slotio.COPIES_AT_ONCE + 20  # the test buffer holds 84 slot records
    seqs, lengths = [2 * k + 2 for k in range(n)], [8] * n
    whole = [k != torn_at for k in range(n)]
    data = bytes(range(256)) * 5
    buf = buffer_with(n, [(seq, *[0] * 7) for seq in seqs], data[: sum(lengths)])
    jobs = [jobs_of(buf, seqs, whole, lengths) for _ in range(2)]
    assert slotio.copies(jobs[0]) == slotio.py_copies(jobs[1]) == (None if torn_at is None else (torn_at, 1))
    for k in range(n if torn_at is None else torn_at):
        assert jobs[0][k][5].tobytes() == jobs[1][k][5].tobytes() == data[8 * k : 8 * k + 8]


@pytest.mark.parametrize("impl", ["c", "python"])
@pytest.mark.parametrize("offset", [0, 3])
def test_a_frame_of_megabytes_is_copied_whole_into_any_alignment(impl, offset):
    """Frames from 512 KiB on are streamed past the caches (C): every byte still arrives."""
    copies = _slotio.copies if impl == "c" else slotio.py_copies
    data = np.random.default_rng(5).integers(0, 256, (1 << 20) + 77, dtype=np.uint8).tobytes()
    buf = buffer_with(1, [(10, *[0] * 7)], data)
    out = np.zeros(len(data) + offset, np.uint8)[offset:]  # a target not aligned to 16 bytes
    assert copies([(buf, TABLE, 10, DATA, len(data), out)]) is None
    assert out.tobytes() == data
