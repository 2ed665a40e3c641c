"""Lines of one kind logged at most once an interval, with a count (fxis_shm.service.logtally),
in virtual time."""

from fxis_shm.service.logtally import LogTally

S = 1_000_000_000


def test_the_first_line_at_once_the_others_counted_and_said_when_the_interval_ends():
    tally = LogTally(10 * S)
    assert tally.note("bad requests", "bad request: 1", 0) == ["bad request: 1"]
    assert all(tally.note("bad requests", f"bad request: {n}", n * S // 1000) == [] for n in range(2, 1001))
    assert tally.note("BUSY", "busy: a", 5 * S) == ["busy: a"]  # another kind: its own interval
    assert tally.flush(10 * S - 1) == []
    assert tally.flush(10 * S) == ["999 more of bad requests in the last 10 s, the last: bad request: 1000"]
    assert tally.flush(11 * S) == []  # said once
    assert tally.note("bad requests", "bad request: 1001", 11 * S) == ["bad request: 1001"]  # a new interval
    assert tally.note("BUSY", "busy: b", 12 * S) == []  # in BUSY's interval, which began at 5 s
    assert tally.note("bad requests", "bad request: 1002", 21 * S) == [
        "1 more of BUSY in the last 10 s, the last: busy: b",
        "bad request: 1002",
    ]


def test_a_kind_seen_once_leaves_no_count_line():
    tally = LogTally(10 * S)
    assert tally.note("changes of camera a", "camera a changed {'gain': 1.0} (live)", 0) == [
        "camera a changed {'gain': 1.0} (live)"
    ]
    assert tally.flush(60 * S) == []
