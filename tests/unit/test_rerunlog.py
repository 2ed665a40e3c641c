"""fxis_shm.formats.rerunlog: the capture_time timeline's kind follows the clock (a wall clock as
dates, any other as a duration), to the nanosecond, and a frame id does not carry over to what is
logged after it. Read back with rerun-sdk's own reader."""

import numpy as np
import pyarrow as pa
import pytest

from fxis_shm.formats.rerunlog import RerunLog, is_wall_clock

from ..integration.rrdread import read_rrd

T_NS = 1_795_885_759_049_886_275  # a CLOCK_REALTIME moment, with nanoseconds a float would lose


@pytest.mark.parametrize(
    ("clock", "wall"),
    [("CLOCK_REALTIME", True), ("realtime", True), ("CLOCK_TAI", True), ("CLOCK_MONOTONIC", False),
     ("monotonic", False), ("the bag's clock", False), (None, False)],
)  # fmt: skip
def test_only_wall_clocks_are_shown_as_dates(clock, wall):
    assert is_wall_clock(clock) is wall


@pytest.mark.parametrize(
    ("clock", "arrow_type"), [("CLOCK_REALTIME", pa.timestamp("ns")), ("CLOCK_MONOTONIC", pa.duration("ns"))]
)
def test_capture_time_is_exact_and_of_the_clocks_kind(tmp_path, clock, arrow_type):
    from rerun.chunk import RrdReader

    log = RerunLog("--rerun", clock, "unit").save(str(tmp_path / "t.rrd"))
    log.image("cam", np.zeros((4, 6), np.uint8), T_NS, frame_id=7)
    log.jpeg("cam", b"\xff\xd8not really", T_NS + 1)  # no frame id: none is carried over from the image
    log.close()
    rows = read_rrd(tmp_path / "t.rrd").entities["/cameras/cam"]
    assert [(r.capture_ns, r.frame_id) for r in rows] == [(T_NS, 7), (T_NS + 1, None)]
    types = {
        chunk.to_record_batch().schema.field("capture_time").type
        for chunk in RrdReader(tmp_path / "t.rrd").stream()
        if "capture_time" in chunk.timeline_names
    }
    assert types == {arrow_type}
