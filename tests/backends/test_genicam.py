"""The ``genicam`` backend against a real GenTL producer: viky.cti, the simulated
producer the genicam wheel ships (three devices, 400x400 RGBa8 at 20 fps, each
drawing a bouncing square: red, green and blue)."""

import json
import os
import time

import numpy as np
import pytest

try:  # `make test` installs the genicam extra; without it these tests must fail, not skip
    import genicam
    import harvesters.core  # noqa: F401
except ImportError as exc:
    raise ImportError(f"the genicam tests need the genicam extra: pip install -e '.[genicam]' ({exc})") from exc

from fxis_shm.service.camerakinds import GENTL_PATH_VAR, camera_options  # noqa: E402
from fxis_shm.workers.backends.genicam import GenicamCamera, producers_from_env  # noqa: E402
from fxis_shm.workers.backends.pixelformats import image_layout, to_image  # noqa: E402

from ..conftest import fxis_run_alone, wait_until  # noqa: E402
from .conftest import fxis  # noqa: E402

pytestmark = pytest.mark.integration

VIKY = os.path.join(os.path.dirname(genicam.__file__), "viky.cti")
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BGR = {"red": (0, 0, 255), "green": (0, 255, 0), "blue": (255, 0, 0)}  # viky devices 0, 1, 2


def half_grey(image):
    """A processing hook (process=tests.backends.test_genicam:half_grey): BGR in, grey at half size out."""
    import cv2

    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return cv2.resize(grey, (image.shape[1] // 2, image.shape[0] // 2), interpolation=cv2.INTER_NEAREST)


def viky(device, **keys) -> str:
    options = {"cti": VIKY, "device": device, **keys}
    return "genicam:" + ",".join(f"{k}={v}" for k, v in options.items())


def colours(image) -> set:
    """The colours of a BGR image other than viky's white background."""
    pixels = image.reshape(-1, 3)
    return {tuple(int(v) for v in p) for p in np.unique(pixels[(pixels != 255).any(axis=1)], axis=0)}


def statuses(svc) -> dict:
    with svc.client() as client:
        return client.status()["cameras"]


def camera(**raw) -> GenicamCamera:
    options = camera_options("g", "genicam", {"cti": VIKY, **raw})
    return GenicamCamera("g", options, time.monotonic_ns())


def test_three_devices_of_one_producer_stream_together(start_service):
    svc = start_service("--camera", f"a={viky(0)}", "--camera", f"b={viky(1)}", "--camera", f"c={viky(2)}")
    cams = wait_until(
        lambda: (s := statuses(svc)) and all(c["frames_stored"] >= 10 for c in s.values()) and s,
        timeout=20,
        what="frames from all three devices",
    )
    for status in cams.values():
        assert status["alive"] and status["shape"] == [400, 400, 3] and status["dtype"] == "uint8"
        assert status["fps"] > 0  # a rate is measured (viky's 20 fps, as fast as this machine fetches)
        assert status["note"] == ""
    with svc.client() as client:
        frames = client.tuple()
    assert set(frames) == {"a", "b", "c"}
    for name, colour in zip("abc", ("red", "green", "blue")):
        image = frames[name].image
        assert image.shape == (400, 400, 3) and image.dtype == np.uint8
        assert colours(image) == {BGR[colour]}  # RGBa8 converted to BGR, the right device
    with svc.client() as client:  # still streaming: newer frames come (a tuple asked at once may be the same)
        wait_until(
            lambda: all(f.frame_id > frames[c].frame_id for c, f in client.tuple().items()),
            timeout=10,
            what="newer frames from every device",
        )
        for name in "abc":  # stored in order, one capture after another
            run = client.sequence("consecutive", camera=name, count=5)
            assert all(b.frame_id > a.frame_id and b.t_capture > a.t_capture for a, b in zip(run, run[1:]))


@pytest.mark.parametrize(
    "keys, words",
    [
        ({"width": 900}, ["key 'width'", "900", "100..800"]),
        ({"pixel_format": "BayerRG8"}, ["key 'pixel_format'", "BayerRG8", "RGBa8, Mono8"]),
        ({"trigger": "software"}, ["key 'trigger'", "TriggerSoftware", "trigger=free"]),
        ({"timestamp": "device"}, ["key 'timestamp'", "timestamp=host"]),
    ],
)
def test_a_configuration_the_device_refuses_stops_start_up(keys, words):
    result = fxis_run_alone("--camera", f"a={viky(0, **keys)}")
    assert result.returncode == 2  # a setting to change (docs/cli.md)
    assert "camera 'a'" in result.stderr, result.stderr
    assert all(w in result.stderr for w in words), result.stderr


def test_a_device_or_producer_that_is_not_there_is_named():
    with pytest.raises(ValueError, match=r"key 'device'.*'7'.*VikyTL_DEV_red"):
        camera(device="7").open()
    with pytest.raises(ValueError, match=r"key 'cti'.*does not exist"):
        camera(cti="/nowhere/producer.cti").open()


def test_devices_are_found_by_serial_number_id_or_index():
    for device in ("VikyTL_DEV_blue", "2"):
        cam = camera(device=device)
        cam.open()
        try:
            assert colours(cam.grab(2.0).image) == {BGR["blue"]}
        finally:
            cam.close()


def test_generic_keys_set_the_device():
    cam = camera(device="1", pixel_format="mono8", width=320, height=240, fps=50)
    cam.open()
    try:
        assert cam.layout.shape == (240, 320) and cam.nominal_period_ns == 20_000_000
        captures = [cam.grab(2.0) for _ in range(3)]
    finally:
        cam.close()
    assert all(c.image.shape == (240, 320) and c.image.dtype == np.uint8 for c in captures)
    ids = [c.frame_id for c in captures]
    assert ids == sorted(ids) and len(set(ids)) == 3


def test_raw_keeps_rgba_as_delivered():
    cam = camera(device="0", raw=True)
    cam.open()
    try:
        image = cam.grab(2.0).image
    finally:
        cam.close()
    assert image.shape == (400, 400, 4)
    square = image[(image[..., :3] != 255).any(axis=2)]
    assert {tuple(int(v) for v in p[:3]) for p in square} == {(255, 0, 0)}  # red, in RGB order


def test_a_reopened_camera_streams_again_with_later_frame_ids():
    """What the worker does after CameraLost: close, then open again in the same process."""
    cam = camera(device="2")
    cam.open()
    try:
        first = cam.grab(2.0).frame_id
        cam.close()
        cam.open()
        again = cam.grab(2.0)
    finally:
        cam.close()
    assert again.frame_id > first and again.image.shape == (400, 400, 3)


def test_discover_lists_the_devices_of_the_environments_producers(monkeypatch):
    monkeypatch.setenv(GENTL_PATH_VAR, os.path.dirname(VIKY))
    assert producers_from_env() == [VIKY]
    found = GenicamCamera.discover()
    assert [c["id"] for c in found] == ["0", "1", "2"]
    assert all("Viky" in c["model"] and c["format"] == "RGBa8" and c["cti"] == VIKY for c in found)
    # and through the CLI, as an operator sees them
    result = fxis("cameras", "--json")
    assert result.returncode == 0, result.stderr
    listed = [c for c in json.loads(result.stdout)["cameras"] if c["kind"] == "genicam"]
    assert [c["id"] for c in listed] == ["0", "1", "2"]


def test_discover_without_producers_says_why(monkeypatch):
    monkeypatch.delenv(GENTL_PATH_VAR, raising=False)
    with pytest.raises(LookupError, match=GENTL_PATH_VAR):
        GenicamCamera.discover()


def test_a_processing_hook_works_with_a_genicam_camera(start_service, monkeypatch):
    monkeypatch.setenv("PYTHONPATH", REPO + os.pathsep + os.environ.get("PYTHONPATH", ""))
    svc = start_service("--camera", f"a={viky(0)},process=tests.backends.test_genicam:half_grey")
    status = wait_until(
        lambda: (s := statuses(svc)["a"])["frames_stored"] >= 3 and s, timeout=20, what="frames through the hook"
    )
    assert status["shape"] == [200, 200] and status["hook_errors"] == 0
    with svc.client() as client:
        frame = client.image("a")
    assert frame.image.shape == (200, 200) and frame.image.dtype == np.uint8
    assert set(np.unique(frame.image)) == {76, 255}  # the red square in grey on white


@pytest.mark.parametrize("pattern, code_pattern", [("RG", "RGGB"), ("BG", "BGGR"), ("GR", "GRBG"), ("GB", "GBRG")])
def test_bayer_patterns_demosaic_to_the_right_colours(pattern, code_pattern):
    """A red scene seen through each GenICam Bayer pattern comes out red in BGR."""
    mosaic = np.zeros((8, 8), np.uint8)
    row, col = divmod(code_pattern.index("R"), 2)
    mosaic[row::2, col::2] = 200
    image = to_image(mosaic.reshape(-1), f"Bayer{pattern}8", 8, 8, raw=False)
    assert image.shape == (8, 8, 3) and tuple(image[4, 4]) == (0, 0, 200)
    assert image_layout(f"Bayer{pattern}8", 8, 8, raw=False).shape == (8, 8, 3)
    assert to_image(mosaic.reshape(-1), f"Bayer{pattern}8", 8, 8, raw=True).shape == (8, 8)


def test_conversions_keep_depth_and_drop_row_padding():
    mono16 = np.arange(4 * 3, dtype=np.uint16)
    assert to_image(mono16.view(np.uint8), "Mono16", 3, 4, raw=False).tolist() == mono16.reshape(4, 3).tolist()
    padded = np.arange(4 * 5, dtype=np.uint8)  # rows of 3 pixels + 2 bytes of padding
    assert to_image(padded, "Mono8", 3, 4, raw=False).tolist() == padded.reshape(4, 5)[:, :3].tolist()
    rgb = np.array([10, 20, 30] * 4, np.uint8)
    assert to_image(rgb, "RGB8", 2, 2, raw=False)[0, 0].tolist() == [30, 20, 10]
