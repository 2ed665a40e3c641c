"""What a newcomer reads from the commands: the ring ordering in fxis status, a recording's
data rate and how long the disk lasts, before the disk fills."""

from __future__ import annotations

import pytest

from ..conftest import fxis
from .conftest import SMALL

pytestmark = pytest.mark.integration


def test_status_shows_the_ring_ordering_the_readme_promises(start_service):
    svc = start_service("--camera", f"a=synthetic:{SMALL}")
    result = fxis("status", "--endpoint", svc.endpoint)
    assert result.returncode == 0 and "ring ordering " in result.stdout.splitlines()[0]


def test_a_recording_says_what_it_writes_a_second_before_it_starts(start_service, tmp_path):
    svc = start_service("--camera", "a=synthetic:fps=20,width=1360,height=1024", "--camera", "b=synthetic:fps=20")
    result = fxis("record", "--endpoint", svc.endpoint, "--out", str(tmp_path / "bag"), "--frames", "2")
    assert result.returncode == 0, result.stderr
    (line,) = [line for line in result.stderr.splitlines() if "MB/s" in line]
    assert "writing about 56 MB/s (raw)" in line and "GB free there" in line and "min" in line
