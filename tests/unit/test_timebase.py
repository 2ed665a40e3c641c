"""The clock's names: one spelling in what the service says, either one read (issue 43)."""

import pytest

from fxis_shm.core import timebase
from fxis_shm.errors import InvalidArgument


@pytest.mark.parametrize("short, posix", list(timebase.WIRE_NAMES.items()))
def test_either_spelling_names_the_same_clock(short, posix):
    assert timebase.check(short) == timebase.check(posix) == short
    assert abs(timebase.reader(posix)() - timebase.reader(short)()) < 1e9  # the same clock read twice


def test_a_status_of_an_older_service_is_read_too():
    assert timebase.of_status({"clock": "monotonic"}) == "monotonic"  # before issue 43
    assert timebase.of_status({"clock": "CLOCK_REALTIME"}) == "realtime"
    assert timebase.of_status({}) == timebase.DEFAULT


def test_an_unknown_clock_is_refused_naming_the_choices():
    with pytest.raises(InvalidArgument, match="monotonic, realtime, tai"):
        timebase.check("CLOCK_BOOTTIME")
