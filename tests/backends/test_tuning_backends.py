"""Settings changed while real GenICam and OpenCV sources stream: the GenTL producer viky.cti
and a video file, each behind a real service (the Aravis fake camera's are in test_aravis.py,
whose module runs its emulators one at a time). Live changes show in the frames with the
generation kept; a size change restarts the stream with a new generation; node-map features
are set by name; refusals leave the camera running."""

import os

import cv2
import genicam
import numpy as np
import pytest

from ..conftest import wait_until
from .tuning_helpers import latest_of, newest_after, refusal

pytestmark = pytest.mark.integration

VIKY = os.path.join(os.path.dirname(genicam.__file__), "viky.cti")


def test_gentl_viky_live_frame_rate_and_feature_and_a_new_size(start_service):
    svc = start_service("--camera", f"g=genicam:cti={VIKY},device=0")
    with svc.client(timeout=15) as client:
        before = newest_after(client, "g", newest_after(client, "g"))
        message = refusal(client, "g", exposure_us=1000)  # viky has no ExposureTime
        assert "has no setting 'exposure_us' (it has: fps, height, pixel_format, trigger, width)" in message
        assert "no TriggerSoftware" in refusal(client, "g", trigger="software")
        answer = client.configure("g", fps=40, BouncingBallSize=40)
        assert answer["cost"] == "live" and answer["changed"] == {"fps": 40.0, "BouncingBallSize": 40}
        assert client.status()["cameras"]["g"]["fps"] == 40.0  # the ring's period, set with the change
        ball = newest_after(client, "g", newest_after(client, "g", before))
        assert ball.image.mean() < before.image.mean() - 0.5, "a bigger ball leaves less white"
        assert ball.generation == before.generation
        assert "BouncingBallSize=41 is out of range: it allows 1..40" in refusal(client, "g", BouncingBallSize=41)
        resized = client.configure("g", width=200)
        assert resized["cost"] == "restart" and resized["generation"] == before.generation + 1
        frame = wait_until(lambda: latest_of(client, "g", resized["generation"]), what="a frame of the new size")
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
        before = newest_after(client, "v")
        for key in ("exposure_us", "gain", "width"):
            assert "a video file plays as it was recorded" in refusal(client, "v", **{key: 1})
        assert "use rate" in refusal(client, "v", fps=5)
        assert "expected file, max or a number of frames per second" in refusal(client, "v", rate="fast")
        assert client.configure("v", loop=False)["cost"] == "live"
        answer = client.configure("v", pixel_format="mono8", loop=True, rate=40)
        assert answer["cost"] == "restart" and answer["generation"] == before.generation + 1
        frame = wait_until(lambda: latest_of(client, "v", answer["generation"]), what="a mono8 frame")
        assert frame.image.shape == (48, 64)
        assert client.status()["cameras"]["v"]["fps"] == 40.0
