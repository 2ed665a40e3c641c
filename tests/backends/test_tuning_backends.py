"""Settings changed while real GenICam cameras stream: the Aravis fake camera
(``arv-fake-gv-camera-0.8``) and the GenTL producer viky.cti, each behind a real service.
Live changes show in the frames with the generation kept; a size change restarts the stream
with a new generation; node-map features are set by name; refusals leave the camera running."""

import os

import cv2
import genicam
import numpy as np
import pytest

from fxis_shm.errors import ServiceError, SettingRejected

from ..conftest import wait_until
from .conftest import fxis

pytestmark = pytest.mark.integration

VIKY = os.path.join(os.path.dirname(genicam.__file__), "viky.cti")


def _latest(client, camera: str, generation: int | None = None):
    """The newest frame of ``camera`` (of ``generation``), None while there is none (a ring just
    made for a new size holds no frame yet)."""
    try:
        frame = client.latest([camera])[camera]
    except ServiceError as exc:
        if exc.code != "NO_FRAMES":
            raise
        return None
    return frame if generation is None or frame.generation == generation else None


def _newest(client, camera: str, after=None):
    """The newest frame of ``camera`` once one newer than ``after`` (a frame) is stored."""

    def newer():
        frame = _latest(client, camera)
        return frame if frame is not None and (after is None or frame.t_capture > after.t_capture) else None

    return wait_until(newer, what=f"a newer frame of {camera}")


def _refused(client, camera: str, **values) -> str:
    with pytest.raises(SettingRejected) as refused:
        client.configure(camera, **values)
    return refused.value.message


def test_aravis_fake_camera_live_exposure_gain_features_and_a_new_size(emulator, start_service):
    cam = emulator()
    svc = start_service("--camera", f"a=aravis:device={cam.device_id},fps=20,width=64,height=48,pixel_format=Mono8")
    with svc.client(timeout=15) as client:
        before = _newest(client, "a", _newest(client, "a"))
        limits = client.settings("a")["limits"]
        assert limits["exposure_us"]["min"] == 10.0 and limits["width"]["cost"] == "restart"
        # the fake camera's picture scales with 1 + gain + log10(exposure / 10 ms)
        answer = client.configure("a", exposure_us=3162.3)
        assert answer["cost"] == "live" and answer["generation"] == before.generation
        assert abs(answer["changed"]["exposure_us"] - 3162.3) < 1
        dark = _newest(client, "a", _newest(client, "a", before))
        assert dark.image.mean() < before.image.mean() * 0.75, (dark.image.mean(), before.image.mean())
        assert dark.generation == before.generation
        client.configure("a", gain=3)
        bright = _newest(client, "a", _newest(client, "a", dark))
        assert bright.image.mean() > dark.image.mean() * 1.5
        # any node-map feature by its SFNC name
        assert client.configure("a", TestRegister=7)["changed"] == {"TestRegister": 7}
        assert client.settings("a")["generation"] == before.generation
        assert "exposure_us=5 is out of range: it allows 10..10000000 us" in _refused(client, "a", exposure_us=5)
        assert "DeviceID of camera 'a' is read-only" in _refused(client, "a", DeviceID="x")
        assert "set it as width" in _refused(client, "a", Width=96)
        assert "has no setting 'Shutter'" in _refused(client, "a", Shutter=1, gain=1)  # all or none
        assert client.settings("a")["values"]["gain"] == 3.0
        resized = client.configure("a", width=96)
        assert resized["cost"] == "restart" and resized["generation"] == before.generation + 1
        frame = wait_until(lambda: _latest(client, "a", resized["generation"]), what="a frame of the new size")
        assert frame.image.shape == (48, 96)
        assert client.settings("a")["values"]["exposure_us"] == answer["changed"]["exposure_us"]  # kept
        triggered = client.configure("a", trigger="software")  # TriggerSoftware from now on
        assert triggered["cost"] == "restart" and client.status()["cameras"]["a"]["trigger"] == "software"
        frame = client.image("a", timeout=5)
        assert frame.generation == triggered["generation"] and frame.image.shape == (48, 96)
    listed = fxis("get", "a", "--features", "--endpoint", svc.endpoint)
    assert listed.returncode == 0, listed.stderr
    assert "ExposureTimeAbs" in listed.stdout and "TestRegister" in listed.stdout and "PixelFormat" in listed.stdout


def test_gentl_viky_live_frame_rate_and_feature_and_a_new_size(start_service):
    svc = start_service("--camera", f"g=genicam:cti={VIKY},device=0")
    with svc.client(timeout=15) as client:
        before = _newest(client, "g", _newest(client, "g"))
        message = _refused(client, "g", exposure_us=1000)  # viky has no ExposureTime
        assert "has no setting 'exposure_us' (it has: fps, height, pixel_format, trigger, width)" in message
        assert "no TriggerSoftware" in _refused(client, "g", trigger="software")
        answer = client.configure("g", fps=40, BouncingBallSize=40)
        assert answer["cost"] == "live" and answer["changed"] == {"fps": 40.0, "BouncingBallSize": 40}
        assert client.status()["cameras"]["g"]["fps"] == 40.0  # the ring's period, set with the change
        ball = _newest(client, "g", _newest(client, "g", before))
        assert ball.image.mean() < before.image.mean() - 0.5, "a bigger ball leaves less white"
        assert ball.generation == before.generation
        assert "BouncingBallSize=41 is out of range: it allows 1..40" in _refused(client, "g", BouncingBallSize=41)
        resized = client.configure("g", width=200)
        assert resized["cost"] == "restart" and resized["generation"] == before.generation + 1
        frame = wait_until(lambda: _latest(client, "g", resized["generation"]), what="a frame of the new size")
        assert frame.image.shape == (400, 200, 3)
        features = {f["name"]: f for f in client.settings("g", features=True)["features"]}
        assert features["BouncingBallSize"]["value"] == 40  # set by name before the restart: set again
        assert features["BouncingBallSize"]["max"] == 40 and features["Width"]["access"] == "ro"


def test_an_opencv_file_takes_what_a_file_can_and_refuses_the_rest(start_service, tmp_path):
    path = str(tmp_path / "grey.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 20.0, (64, 48))
    for k in range(20):
        writer.write(np.full((48, 64, 3), 10 * k, np.uint8))
    writer.release()
    svc = start_service("--camera", f"v=opencv:source={path},loop=true")
    with svc.client(timeout=15) as client:
        before = _newest(client, "v")
        for key in ("exposure_us", "gain", "width"):
            assert "a video file plays as it was recorded" in _refused(client, "v", **{key: 1})
        assert "use rate" in _refused(client, "v", fps=5)
        assert "expected file, max or a number of frames per second" in _refused(client, "v", rate="fast")
        assert client.configure("v", loop=False)["cost"] == "live"
        answer = client.configure("v", pixel_format="mono8", loop=True, rate=40)
        assert answer["cost"] == "restart" and answer["generation"] == before.generation + 1
        frame = wait_until(lambda: _latest(client, "v", answer["generation"]), what="a mono8 frame")
        assert frame.image.shape == (48, 64)
        assert client.status()["cameras"]["v"]["fps"] == 40.0
