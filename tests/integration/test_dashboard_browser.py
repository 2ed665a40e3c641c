"""The dashboard in a real browser: headless Chromium loads the page of a real service,
every camera's picture is drawn and moves, and a camera worker killed with kill -9 is
shown DOWN. Screenshots are kept in the test's tmp_path (dashboard-*.png)."""

from __future__ import annotations

import os
import signal

import cv2
import numpy as np
import pytest

from .browser import Browser, find_chromium
from .conftest import child_pids
from .test_dashboard import get, start_dashboard, view

pytestmark = pytest.mark.integration

# what the page's JavaScript reports of each camera tile
TILES_JS = """Array.from(document.querySelectorAll('.camera')).map(tile => {
  const img = tile.querySelector('img'), box = img.getBoundingClientRect();
  return {name: tile.dataset.camera, state: tile.dataset.state,
          badge: tile.querySelector('.badge').textContent, why: tile.querySelector('.why').textContent,
          loaded: img.complete && img.naturalWidth > 0, natural: [img.naturalWidth, img.naturalHeight],
          box: {x: box.left + scrollX, y: box.top + scrollY, width: box.width, height: box.height}};
})"""
SYNC_JS = "document.getElementById('sync').textContent"
PTP_JS = """Array.from(document.querySelectorAll('.camera table tr'))
  .filter(tr => tr.cells[0].textContent === 'ptp').map(tr => tr.cells[1].textContent)"""
PAGE_WIDTH = 480  # the page's default picture width: wider cameras are scaled down to it
SIZES = {"a": (320, 240), "b": (64, 48)}  # CAMERAS' sizes, narrower than PAGE_WIDTH: as they are


def tiles(browser: Browser) -> dict[str, dict]:
    return {t["name"]: t for t in browser.evaluate(TILES_JS)}


def picture(browser: Browser, tile: dict) -> np.ndarray:
    """The camera's picture as the browser draws it (a screenshot of its <img>)."""
    png = browser.screenshot(tile["box"])
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)


@pytest.fixture
def browser(tmp_path):
    executable = find_chromium()
    if executable is None:
        pytest.fail(
            "chromium is not installed: the dashboard's browser test needs Debian's "
            "chromium package (scripts/install-system-packages.sh installs it)"
        )
    with Browser(tmp_path / "chromium", executable) as b:
        yield b


def test_the_page_shows_every_camera_live_and_a_killed_one_down(browser, start_service, wait, tmp_path):
    svc, base = start_dashboard(start_service, wait)  # --restart-limit 0: a killed camera stays down
    browser.open(base + "/")

    # every camera has a tile with its picture loaded, at the camera's size (none is wider
    # than the page's default width), live
    def all_loaded():
        shown = tiles(browser)
        return shown if set(shown) == set(SIZES) and all(t["loaded"] for t in shown.values()) else None

    shown = wait(all_loaded, timeout=30, interval=0.2, what="every camera's picture on the page")
    for name, tile in shown.items():
        assert tuple(tile["natural"]) == SIZES[name], (name, tile)
        assert tile["state"] == "up" and tile["badge"] == "live", tile
        assert tile["box"]["width"] == SIZES[name][0]  # drawn at its own size, not stretched
    # the live sync figures (fxis sync-report's): the two cameras share a time origin, so PASS;
    # each tile shows its PTP state (a synthetic camera cannot say: "-")
    sync = wait(lambda: (t := browser.evaluate(SYNC_JS)).startswith("sync PASS") and t, timeout=30, interval=0.2,
                what="the sync figures on the page")  # fmt: skip
    assert "gap p50 0.000" in sync and "synced 100.0 %" in sync, sync
    assert browser.evaluate(PTP_JS) == ["-", "-"]
    (tmp_path / "dashboard-live.png").write_bytes(browser.screenshot())

    # what the browser draws of each camera is a picture (not a blank box) and it changes
    first = {name: picture(browser, tile) for name, tile in shown.items()}
    for name, image in first.items():
        assert image.shape[:2] == SIZES[name][::-1] and image.std() > 5, f"{name}: a blank picture"
    for name, tile in shown.items():
        wait(
            lambda tile=tile, name=name: not np.array_equal(picture(browser, tile), first[name]),
            timeout=20,
            interval=0.2,
            what=f"camera {name}'s picture to change on the page",
        )

    # kill -9 of camera b's worker (--restart-limit 0: it stays down) shows on the page
    with svc.client() as client:
        pid = client.status()["supervisor"]["processes"]["camera:b"]["pid"]
    assert pid in child_pids(svc, "camera")
    os.kill(pid, signal.SIGKILL)
    down = wait(
        lambda: (lambda t: t["b"]["state"] == "down" and t)(tiles(browser)),
        timeout=20,
        interval=0.2,
        what="camera b shown DOWN on the page",
    )
    (tmp_path / "dashboard-b-down.png").write_bytes(browser.screenshot())
    assert down["b"]["badge"] == "DOWN" and down["b"]["why"], down["b"]
    assert down["a"]["state"] == "up" and down["a"]["badge"] == "live"  # the other goes on
    before = picture(browser, down["a"])
    wait(
        lambda: not np.array_equal(picture(browser, down["a"]), before),
        timeout=20,
        interval=0.2,
        what="camera a's picture to keep changing",
    )
    assert get(base + "/cameras/b/latest.jpg")[0] == 503
    # its tuples come without b from now on: dropped, until the figures fail
    failed = wait(lambda: (t := browser.evaluate(SYNC_JS)).startswith("sync FAIL") and t, timeout=30, interval=0.2,
                  what="the sync figures to fail")  # fmt: skip
    assert "dropped" in failed


# the skew plot as the page draws it: its bound line, its axes' ticks (value, position), its points
SKEW_PLOT_JS = """(() => {
  const svg = document.getElementById('skew'), num = (e, a) => parseFloat(e.getAttribute(a));
  if (!svg) return null;  // the page is not there yet
  const bound = svg.querySelector('line.bound'), series = svg.querySelector('polyline.series');
  return {
    bound: bound && {value: num(bound, 'data-value'), y: num(bound, 'y1')},
    yticks: Array.from(svg.querySelectorAll('text.ytick')).map(t => [num(t, 'data-value'), num(t, 'y') - 4]),
    xticks: Array.from(svg.querySelectorAll('text.xtick')).map(t => [num(t, 'data-value'), num(t, 'x'), t.textContent]),
    points: series ? series.getAttribute('points').trim().split(' ').map(p => p.split(',').map(Number)) : [],
    right: svg.width.baseVal.value - 8,
    box: (b => ({x: b.left + scrollX, y: b.top + scrollY, width: b.width, height: b.height}))(
      svg.getBoundingClientRect()),
  };
})()"""


def test_the_skew_plot_shows_its_bound_against_seconds_ago(browser, start_service, wait, tmp_path):
    """Issue 43: the skew plot had no threshold line and an x axis in absolute seconds (since the
    dashboard started). Now the sync figures' bound is a line at its height on the y axis, and
    the x axis runs in round seconds ago to "now" at the right edge, every point left of it."""
    svc, base = start_dashboard(start_service, wait)
    assert view(base)["skew_bound_ms"] == 3.0  # the threshold the sync figures count "synced" by
    browser.open(base + "/")
    shown = wait(lambda: (p := browser.evaluate(SKEW_PLOT_JS)) and p["bound"] and len(p["points"]) >= 4 and p,
                 timeout=30, interval=0.2, what="4 skews plotted")  # fmt: skip
    browser.evaluate("document.getElementById('skew').scrollIntoView()")  # a screenshot sees the viewport
    (tmp_path / "dashboard-skew.png").write_bytes(browser.screenshot(browser.evaluate(SKEW_PLOT_JS)["box"]))
    # y: round, evenly spaced ticks from 0; the bound is drawn where 3 ms is on that scale
    values, ys = zip(*shown["yticks"])
    steps = {round(b - a, 9) for a, b in zip(values, values[1:])}
    assert values[0] == 0 and len(steps) == 1 and values[-1] >= 3.0, values
    px_per_ms = (ys[0] - ys[-1]) / values[-1]
    assert shown["bound"]["value"] == 3.0
    assert abs(shown["bound"]["y"] - (ys[0] - 3.0 * px_per_ms)) < 0.5, (shown["bound"], shown["yticks"])
    # x: seconds ago, evenly spaced, "now" at the right edge; every point between the oldest tick and now
    seconds, xs, labels = zip(*shown["xticks"])
    assert labels[-1] == "now" and seconds[-1] == 0 and xs[-1] == shown["right"], shown["xticks"]
    assert all(label == f"{-s:g} s ago" for s, label in zip(seconds[:-1], labels[:-1])), labels
    assert len({round(b - a, 9) for a, b in zip(seconds, seconds[1:])}) == 1 and seconds[0] < 0
    point_xs = [x for x, _ in shown["points"]]
    assert point_xs == sorted(point_xs) and xs[0] <= point_xs[0] and point_xs[-1] <= xs[-1], (point_xs, xs)
