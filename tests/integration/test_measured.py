"""Figures that are what they say (issue 33, findings 8, 9 and 18's age_ms): ``fxis status``
shows the rate measured over a stated window beside the set one, so a camera that drops
frames shows it; the dashboard's interval plot shows dropped frames as spikes; the age of the
newest frame has fixed decimals. A real service, its camera dropping 30 % of its frames
(seeded: the same frames every run)."""

from __future__ import annotations

import json
import re

import pytest

from fxis_shm.service.launch import free_tcp_port
from fxis_shm.viewers.livefeed import INTERVALS_SHOWN

from ..conftest import fxis, wait_until
from .conftest import SMALL
from .test_dashboard import view

pytestmark = pytest.mark.integration


@pytest.fixture
def dropping(start_service):
    port = free_tcp_port()
    svc = start_service(
        "--camera",
        f"lossy=synthetic:fps=20,drop=0.3,seed=7,{SMALL}",
        "--camera",
        f"whole=synthetic:fps=20,{SMALL}",
        "--history",
        "6",
        http=f"127.0.0.1:{port}",
    )
    with svc.client() as client:
        wait_until(lambda: client.status()["uptime_s"] > 6, timeout=20, what="5 s of frames to measure")
    return svc, f"http://127.0.0.1:{port}"


def test_status_shows_the_measured_rate_over_its_window_beside_the_set_one(dropping):
    svc, _ = dropping
    result = fxis("status", "--endpoint", svc.endpoint, "--json")
    assert result.returncode == 0, result.stderr
    cameras = json.loads(result.stdout)["cameras"]
    lossy, whole = cameras["lossy"], cameras["whole"]
    assert lossy["fps"] == whole["fps"] == 20.0  # the set rate
    assert lossy["measured_over_s"] == whole["measured_over_s"] == 5.0
    assert lossy["measured_fps"] <= 20 * 0.85, lossy  # 30 % of its frames dropped: it shows
    assert 0 < whole["measured_fps"] <= 20 * 1.05, whole

    table = fxis("status", "--endpoint", svc.endpoint).stdout.splitlines()
    header = next(line for line in table if line.startswith("camera"))
    assert "fps (last 5 s)" in header and "set fps" in header and "age_ms" in header
    columns = re.split(r"\s{2,}", header)
    row = dict(zip(columns, re.split(r"\s{2,}", next(line for line in table if line.startswith("lossy")))))
    assert float(row["fps (last 5 s)"]) <= 17.0 and row["set fps"] == "20"
    assert re.fullmatch(r"\d+\.\d", row["age_ms"]), row  # one decimal, always


def test_the_interval_plot_shows_dropped_frames_as_spikes(dropping):
    _, base = dropping

    def intervals() -> dict:
        cameras = view(base).get("cameras") or {}
        return cameras if len(cameras.get("lossy", {}).get("intervals_ms", [])) >= INTERVALS_SHOWN else None

    cameras = wait_until(intervals, timeout=20, what="60 intervals plotted")
    lossy = cameras["lossy"]["intervals_ms"]
    assert len(lossy) == INTERVALS_SHOWN  # one per stored frame: none skipped at a gap in the ids
    # 3 in 10 frames dropped: an interval of two periods or more among the last ones plotted
    assert max(lossy) >= 95.0, lossy
