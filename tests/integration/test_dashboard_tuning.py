"""The dashboard's camera controls driven in headless Chromium: the exposure control of a
camera's card changes the camera (the picture on the page gets darker), a value the camera
refuses is shown as refused, and the settings endpoint answers GET and POST."""

from __future__ import annotations

import json
import urllib.error
import urllib.request

import pytest

from fxis_shm.service.launch import free_tcp_port

from .conftest import SMALL
from .test_dashboard import _seen, start_dashboard
from .test_dashboard_browser import browser, picture, tiles  # noqa: F401  (the fixture, by name)

pytestmark = pytest.mark.integration

CONTROL_JS = """(() => {
  const tile = document.querySelector('.camera[data-camera="a"]');
  const number = tile && tile.querySelector('input[type=number][data-key="%s"]');
  const slider = tile && tile.querySelector('input[type=range][data-key="%s"]');
  return number ? {value: Number(number.value), min: Number(number.min), max: Number(number.max),
                   slider: slider !== null, said: tile.querySelector('.said').textContent,
                   state: tile.querySelector('.said').dataset.state || ""} : null;
})()"""
SET_JS = """(() => {
  const number = document.querySelector('.camera[data-camera="a"] input[type=number][data-key="%s"]');
  number.value = %s; number.dispatchEvent(new Event('change'));
  return true;
})()"""


def _post(url: str, body: dict) -> tuple[int, str]:
    request = urllib.request.Request(
        url, data=json.dumps(body).encode(), headers={"Content-Type": "application/json"}, method="POST"
    )
    try:
        with urllib.request.urlopen(request, timeout=20) as answer:
            return answer.status, answer.read().decode()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read().decode()


def test_the_exposure_control_changes_the_camera_and_the_picture(browser, start_service, wait, tmp_path):  # noqa: F811
    svc, base = start_dashboard(start_service, wait)
    browser.open(base + "/")
    control = wait(
        lambda: browser.evaluate(CONTROL_JS % ("exposure_us", "exposure_us")),
        timeout=30,
        interval=0.2,
        what="the exposure control of camera a",
    )
    assert (control["value"], control["min"], control["max"], control["slider"]) == (10_000, 1, 1_000_000, True)
    for key in ("gain", "fps"):  # the other controls, with the camera's ranges
        assert browser.evaluate(CONTROL_JS % (key, key)) is not None, key
    tile = wait(
        lambda: tiles(browser).get("a") if tiles(browser).get("a", {}).get("loaded") else None,
        timeout=30,
        what="camera a's picture",
    )
    before = picture(browser, tile).mean()

    browser.evaluate(SET_JS % ("exposure_us", 2500))
    said = wait(
        lambda: (
            (c := browser.evaluate(CONTROL_JS % ("exposure_us", "exposure_us")))["said"] == "exposure_us = 2500" and c
        ),
        timeout=20,
        what="the camera's answer on the card",
    )
    assert said["state"] == ""
    wait(
        lambda: picture(browser, tiles(browser)["a"]).mean() < before * 0.5,
        timeout=20,
        interval=0.2,
        what="the picture on the page to get darker",
    )
    (tmp_path / "dashboard-darker.png").write_bytes(browser.screenshot())
    with svc.client() as client:
        assert client.settings("a")["values"]["exposure_us"] == 2500.0

    browser.evaluate(SET_JS % ("exposure_us", 0))  # below the camera's range: refused, shown so
    refused = wait(
        lambda: (c := browser.evaluate(CONTROL_JS % ("exposure_us", "exposure_us")))["state"] == "refused" and c,
        timeout=20,
        what="the refusal on the card",
    )
    assert "out of range: it allows 1..1000000 us" in refused["said"]

    status, body = _post(base + "/cameras/a/settings.json", {"gain": 6})
    assert status == 200 and json.loads(body)["changed"] == {"gain": 6.0}
    assert _post(base + "/cameras/a/settings.json", {"gain": 99})[0] == 400
    assert _post(base + "/cameras/a/settings.json", ["gain"])[0] == 400
    assert _post(base + "/cameras/zz/settings.json", {"gain": 1})[0] == 404


def test_a_lockstep_camera_has_no_frame_rate_control(browser, start_service, wait):  # noqa: F811
    """On the lockstep grid the grid sets the rate: the camera says fps is read-only (and why),
    and its card offers exposure and gain but no frame rate."""
    port = free_tcp_port()
    lockstep = ["--lockstep", "20", "--camera", f"a=synthetic:trigger=software,{SMALL}"]
    svc, base = _seen(start_service(*lockstep, http=f"127.0.0.1:{port}"), port)
    browser.open(base + "/")
    wait(
        lambda: browser.evaluate(CONTROL_JS % ("exposure_us", "exposure_us")),
        timeout=30,
        interval=0.2,
        what="the exposure control of camera a",
    )
    assert browser.evaluate(CONTROL_JS % ("gain", "gain")) is not None
    assert browser.evaluate(CONTROL_JS % ("fps", "fps")) is None
