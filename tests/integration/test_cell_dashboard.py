"""``fxis dashboard tcp://a tcp://b``: one page for a cell of services on emulated hosts with
clocks of their own (issue 21, item 3): every camera of both hosts live in Chromium, each
service's health and clock, "Save tuple" across hosts, and a host that stops shown as gone."""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
import urllib.error
import zipfile

import pytest

from fxis_shm.service.launch import free_tcp_port

from ..conftest import wait_until
from .conftest import SMALL
from .test_dashboard import get
from .test_dashboard_browser import TILES_JS, browser  # noqa: F401  (the fixture)

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def cell(module_hosts, tmp_path_factory):
    """Two hosts, a camera on each, and ``fxis dashboard`` over both on this host: shared by
    the tests that only read from them."""
    yield from _cell(module_hosts, tmp_path_factory.mktemp("cell"))


@pytest.fixture
def cell_to_stop(emulated_hosts, tmp_path):
    """A test's own, for the test that stops a host's service."""
    yield from _cell(emulated_hosts, tmp_path)


def _cell(lab, folder):
    a = lab.host(clock_offset_s=1000)
    b = lab.host(clock_offset_s=3000)
    sa = a.service("--camera", f"left=synthetic:fps=20,{SMALL}")
    sb = b.service("--camera", f"right=synthetic:fps=20,phase_ms=9,{SMALL}")
    keys = os.path.join(lab._keys_dir, "keys")
    key_options = ["--server-key", os.path.join(keys, "server.key")]
    key_options += ["--client-key", os.path.join(keys, "client.key_secret")]
    with cell_dashboard([sa.endpoint, sb.endpoint, *key_options], folder / "dashboard.out") as base:
        wait_until(lambda: _all_answer(base), timeout=60, what="the cell dashboard's first look at both hosts")
        yield base, (a, sa), (b, sb)


@contextlib.contextmanager
def cell_dashboard(args: list[str], log_path):
    """``fxis dashboard ARGS`` on a free port of this host, its output in ``log_path`` (printed
    at the end: shown when a test fails); its base URL."""
    port = free_tcp_port()
    out = open(log_path, "w+")
    command = [sys.executable, "-m", "fxis_shm.cli", "dashboard", *args, "--http", f"127.0.0.1:{port}"]
    dashboard = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        dashboard.terminate()
        dashboard.wait(15)
        out.seek(0)
        print(out.read())
        out.close()


def _view(base: str) -> dict:
    try:
        status, _, body = get(base + "/dashboard.json")
    except urllib.error.URLError:  # not listening yet
        return {}
    return json.loads(body) if status == 200 else {}


def _all_answer(base: str) -> dict | None:
    view = _view(base)
    services = view.get("services") or {}
    return view if len(services) == 2 and all(s["ok"] for s in services.values()) else None


def test_the_cell_page_holds_both_hosts_cameras_services_and_clocks(cell):
    base, (a, sa), (b, sb) = cell
    view = _all_answer(base)
    assert set(view["configured"]) == {"left", "right"}
    assert {n: c["service"] for n, c in view["status"]["cameras"].items()} == {
        "left": sa.endpoint,
        "right": sb.endpoint,
    }
    for host, svc in ((a, sa), (b, sb)):
        service = view["services"][svc.endpoint]
        clock = service["clock"]
        assert clock["method"] == "estimated"
        # the host's clock is ahead by its namespace's offset: the page shows it, to its uncertainty
        assert abs(clock["offset_ms"] - host.clock_offset_ns / 1e6) <= clock["uncertainty_ms"] + 1.0
    skews = wait_until(lambda: _view(base).get("skew_ms"), timeout=20, what="the skew of a tuple across hosts")
    assert all(0 <= ms <= 50 for _, ms in skews)  # two 20 fps cameras: at most half a period apart, plus the estimate


def test_save_tuple_takes_a_tuple_across_hosts(cell):
    base, *_ = cell
    status, headers, body = get(base + "/tuple.zip")
    assert status == 200 and headers["Content-Type"] == "application/zip"
    with zipfile.ZipFile(io.BytesIO(body)) as archive:
        names = set(archive.namelist())
        assert {"left.png", "right.png", "tuple.json"} <= names
        described = json.loads(archive.read("tuple.json"))
    assert set(described["frames"]) == {"left", "right"} and described["missing"] == []
    assert described["skew_ns"] <= 50_000_000


def test_in_chromium_both_hosts_are_live_and_a_host_that_stops_shows_as_gone(cell_to_stop, browser):  # noqa: F811
    base, _, (_, sb) = cell_to_stop
    browser.open(base + "/")

    def tiles() -> dict:
        return {t["name"]: t for t in browser.evaluate(TILES_JS)}

    def live() -> dict | None:
        shown = tiles()
        both = set(shown) == {"left", "right"}
        return shown if both and all(t["loaded"] and t["state"] == "up" for t in shown.values()) else None

    wait_until(live, timeout=30, interval=0.2, what="both hosts' cameras live on the page")
    rows = browser.evaluate("Array.from(document.querySelectorAll('#services tr')).map(r => r.dataset.state || '')")
    assert rows.count("ok") == 2
    sb.stop()

    def right_gone() -> dict | None:
        # (a picture that failed may say why first: its request timed out; the service's
        # status, sampled twice a second, then names the service that does not answer)
        shown = tiles()
        return shown if shown["right"]["state"] == "down" and "does not answer" in shown["right"]["why"] else None

    shown = wait_until(right_gone, timeout=30, interval=0.2, what="the stopped host's camera shown down")
    assert sb.endpoint in shown["right"]["why"]
    assert shown["left"]["state"] == "up"
    banner = wait_until(
        lambda: browser.evaluate(
            "(b => b.dataset.state === 'gone' ? b.textContent : null)(document.getElementById('banner'))"
        ),
        timeout=30,
        interval=0.2,
        what="the banner to name the host that stopped",
    )
    assert sb.endpoint in banner and "1 answering" in banner
    rows = browser.evaluate("Array.from(document.querySelectorAll('#services tr')).map(r => r.dataset.state || '')")
    assert sorted(rows) == ["", "gone", "ok"]  # the header, the stopped host, the other
    sb.start()
    wait_until(live, timeout=60, interval=0.2, what="the host back on the page")
