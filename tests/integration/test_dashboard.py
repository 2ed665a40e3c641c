"""The live dashboard (fxis run --http): a real service, its dashboard process, real HTTP."""

from __future__ import annotations

import io
import json
import os
import signal
import urllib.error
import urllib.request
import zipfile

import cv2
import numpy as np
import pytest

from fxis_shm import read_stamp
from fxis_shm.service.launch import free_tcp_port

from ..conftest import fxis, fxis_run_alone, wait_until
from .conftest import SMALL, client_keys, module_services

pytestmark = pytest.mark.integration

CAMERAS = ["--camera", "a=synthetic:fps=20,width=320,height=240", "--camera", f"b=synthetic:fps=10,{SMALL}"]


def get(url: str, timeout: float = 10.0) -> tuple[int, dict, bytes]:
    """(status, headers, body) of a GET, errors included."""
    try:
        with urllib.request.urlopen(url, timeout=timeout) as answer:
            return answer.status, dict(answer.headers), answer.read()
    except urllib.error.HTTPError as exc:
        return exc.code, dict(exc.headers), exc.read()


def view(base: str) -> dict:
    return json.loads(get(base + "/dashboard.json")[2])


def service_ok(base: str) -> bool:
    """Whether the dashboard answers and sees the service (False while it starts, too)."""
    try:
        return view(base)["service_ok"]
    except urllib.error.URLError:  # not listening yet: the service answers before its dashboard
        return False


def jpeg(body: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_UNCHANGED)


@pytest.fixture(scope="module")
def dashboard():
    """Shared by the tests that only read from the dashboard and its service."""
    port = free_tcp_port()
    for (svc,) in module_services([*CAMERAS, "--restart-limit", "0"], http=f"127.0.0.1:{port}"):
        yield _seen(svc, port)


@pytest.fixture
def own_dashboard(start_service, wait):
    """A test's own, for the tests that stop its processes or count its work."""
    return start_dashboard(start_service, wait)


def start_dashboard(start_service, wait):
    """A service with two cameras and its dashboard: (service, base URL)."""
    port = free_tcp_port()
    return _seen(start_service(*CAMERAS, "--restart-limit", "0", http=f"127.0.0.1:{port}"), port)


def _seen(svc, port: int):
    base = f"http://127.0.0.1:{port}"
    wait_until(lambda: service_ok(base), timeout=20, what="the dashboard's first look at the service")
    return svc, base


def test_the_page_and_status_are_served(dashboard):
    svc, base = dashboard
    status, headers, body = get(base + "/")
    assert status == 200 and headers["Content-Type"].startswith("text/html")
    assert b"Save tuple" in body and b"http://" not in body.replace(b"http://www.w3.org/2000/svg", b"")  # offline
    status, _, body = get(base + "/status.json")
    reply = json.loads(body)
    assert status == 200 and reply["service"] == svc.name and set(reply["cameras"]) == {"a", "b"}
    assert reply["supervisor"]["processes"]["dashboard"]["state"] == "running"


def test_the_clock_has_one_spelling_on_every_face(dashboard):
    """Issue 43: /status.json said "monotonic", the settings reply "CLOCK_MONOTONIC". Every reply's
    header, status, the dashboard's /status.json and the command line's JSON name it alike."""
    svc, base = dashboard
    with svc.client() as client:
        said = {
            "status": client.status()["clock"],
            "settings": client.settings("a")["clock"],
            "/status.json": json.loads(get(base + "/status.json")[2])["clock"],
            "/dashboard.json": view(base)["status"]["clock"],
        }
    for argv in (["status", "--json"], ["get", "a", "--json"]):
        said[" ".join(argv)] = json.loads(fxis(*argv, "--endpoint", svc.endpoint).stdout)["clock"]
    assert set(said.values()) == {"CLOCK_MONOTONIC"}, said


def test_the_sync_figures_are_shown_live(dashboard, wait):
    """fxis sync-report's figures over the tuples the dashboard samples: the two cameras share a
    time origin (a at 20 fps, b at 10), so every tuple's frames are of one moment."""
    svc, base = dashboard
    sync = wait(lambda: (v := view(base).get("sync")) and v["slots"] >= 6 and v, timeout=30, what="6 sampled tuples")
    assert sync["verdict"] == "PASS" and sync["gap_ms"]["max"] == 0.0 and sync["synced_pct"] == 100.0
    assert sync["dropped_pct"] <= 5.0 and sync["window_s"] > 0
    for name in ("a", "b"):
        cam = sync["cameras"][name]
        assert cam["captures"]["free"] == sync["slots"] - cam["missing"] and cam["repeated"] == 0
    assert sync["cameras"]["a"]["period_ms"] == 50.0 and sync["cameras"]["b"]["period_ms"] == 100.0
    page = get(base + "/")[2]
    assert b'id="sync"' in page and b"function drawSync" in page and b"function ptpText" in page


def test_pictures_are_the_newest_frames_scaled_down(dashboard, wait):
    svc, base = dashboard
    status, headers, body = get(base + "/cameras/a/latest.jpg?width=160")
    assert status == 200 and headers["Content-Type"] == "image/jpeg"
    assert jpeg(body).shape == (120, 160)
    status, _, body = get(base + "/cameras/b/latest.jpg")  # narrower than the default: as it is
    assert jpeg(body).shape == (48, 64)
    first = headers["X-Fxis-Frame"]
    wait(lambda: get(base + "/cameras/a/latest.jpg?width=160")[1]["X-Fxis-Frame"] != first, what="a newer frame")


def test_each_frame_shown_is_encoded_once_however_often_it_is_asked_for(own_dashboard):
    svc, base = own_dashboard
    before = view(base)["previews_encoded"]
    frames = {get(base + "/cameras/b/latest.jpg?width=33")[1]["X-Fxis-Frame"] for _ in range(12)}
    assert view(base)["previews_encoded"] - before == len(frames) < 12


def test_the_mjpeg_stream_sends_distinct_frames_at_the_asked_rate(dashboard):
    svc, base = dashboard
    with urllib.request.urlopen(base + "/cameras/a/stream.mjpg?fps=10&width=80", timeout=10) as answer:
        assert answer.headers["Content-Type"].startswith("multipart/x-mixed-replace")
        data = b""
        while data.count(b"--fxisframe") < 4:
            chunk = answer.read1(65536)
            assert chunk, "the stream ended"
            data += chunk
    part = data.split(b"--fxisframe")[1]
    image = jpeg(part.split(b"\r\n\r\n", 1)[1].rsplit(b"\r\n", 1)[0])
    assert image.shape == (60, 80)


@pytest.mark.parametrize(
    "path, code, words",
    [
        ("/cameras/nope/latest.jpg", 404, "no camera 'nope'"),
        ("/cameras/nope/stream.mjpg", 404, "known: a, b"),
        ("/cameras/a/latest.jpg?width=abc", 400, "width must be a whole number"),
        ("/cameras/a/latest.jpg?width=0", 400, "width must be from 1"),
        ("/cameras/a/stream.mjpg?fps=-1", 400, "fps must be > 0"),
        ("/cameras/a/stream.mjpg?fps=abc", 400, "fps must be a number"),
    ],
)
def test_bad_requests_get_a_readable_error_and_the_service_keeps_serving(dashboard, path, code, words):
    svc, base = dashboard
    status, _, body = get(base + path)
    assert status == code and words in body.decode()
    assert get(base + "/cameras/a/latest.jpg")[0] == 200


def test_the_save_button_gives_a_zip_of_pngs_and_the_tuple(dashboard):
    svc, base = dashboard
    status, headers, body = get(base + "/tuple.zip")
    assert status == 200 and "attachment" in headers["Content-Disposition"]
    with zipfile.ZipFile(io.BytesIO(body)) as archive:
        assert sorted(archive.namelist()) == ["a.png", "b.png", "tuple.json"]
        meta = json.loads(archive.read("tuple.json"))
        for frame in meta["frames"].values():
            image = cv2.imdecode(np.frombuffer(archive.read(frame["file"]), np.uint8), cv2.IMREAD_UNCHANGED)
            assert image.shape == tuple(frame["shape"]) and read_stamp(image) == frame["frame_id"]


def test_a_killed_camera_worker_shows_as_down(own_dashboard, wait):
    svc, base = own_dashboard
    pid = json.loads(get(base + "/status.json")[2])["supervisor"]["processes"]["camera:b"]["pid"]
    os.kill(pid, signal.SIGKILL)  # --restart-limit 0: it stays down
    wait(lambda: not view(base)["status"]["cameras"]["b"]["alive"], timeout=15, what="b shown down")
    status, _, body = get(base + "/cameras/b/latest.jpg")
    assert status == 503 and "b" in body.decode()
    assert get(base + "/cameras/a/latest.jpg")[0] == 200  # the others go on
    with zipfile.ZipFile(io.BytesIO(get(base + "/tuple.zip")[2])) as archive:  # a partial tuple
        assert json.loads(archive.read("tuple.json"))["missing"] == ["b"]


def test_a_silent_service_is_shown_as_gone_and_back(own_dashboard, wait):
    svc, base = own_dashboard
    pid = json.loads(get(base + "/status.json")[2])["supervisor"]["processes"]["coordinator"]["pid"]
    os.kill(pid, signal.SIGSTOP)
    try:
        shown = wait(
            lambda: (lambda v: not v["service_ok"] and v)(view(base)),
            timeout=15,
            what="the service shown as not answering",
        )
        assert "does not answer" in shown["error"]
        assert get(base + "/status.json")[0] == 503
    finally:
        os.kill(pid, signal.SIGCONT)
    wait(lambda: view(base)["service_ok"], timeout=15, what="the service shown as back")


def test_a_killed_dashboard_is_restarted(start_service, wait):
    port = free_tcp_port()
    svc = start_service(*CAMERAS, http=f"127.0.0.1:{port}")
    base = f"http://127.0.0.1:{port}"
    wait(lambda: service_ok(base), timeout=20, what="the dashboard to answer")
    with svc.client() as client:
        pid = client.status()["supervisor"]["processes"]["dashboard"]["pid"]
        os.kill(pid, signal.SIGKILL)
        wait(
            lambda: client.status()["supervisor"]["processes"]["dashboard"]["restarts"] == 1,
            timeout=20,
            what="the dashboard restarted",
        )
    wait(lambda: service_ok(base), timeout=20, what="the restarted dashboard to answer")


def test_a_port_in_use_stops_start_up_naming_the_dashboard():
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        result = fxis_run_alone("--camera", f"a=synthetic:{SMALL}", "--http", f"127.0.0.1:{port}")
    assert result.returncode == 2  # a bad setting, found before anything started (issue 24)
    assert f"--http 127.0.0.1:{port}" in result.stderr and "in use" in result.stderr, result.stderr


# Real time: "no frame dropped" holds while the camera's worker gets the CPU; one held up longer
# than its driver's buffers (12 frames; the parallel pass, 2 cores) drops frames, viewers or not.
@pytest.mark.realtime
def test_a_viewer_that_stops_reading_holds_up_nobody(dashboard):
    svc, base = dashboard
    url = base + "/cameras/a/stream.mjpg?fps=20&width=320"
    with urllib.request.urlopen(url, timeout=10) as stalled:  # opened, then never read
        stalled.read1(1)
        with svc.client() as client:
            before = client.status()["cameras"]["a"]
        with urllib.request.urlopen(url, timeout=10) as reader:
            data = b""
            while data.count(b"--fxisframe") < 30:  # 1.5 s of pictures while the other is unread
                chunk = reader.read1(65536)
                assert chunk, "the stream ended"
                data += chunk
        with svc.client() as client:
            after = client.status()["cameras"]["a"]
    assert after["frames_stored"] > before["frames_stored"]
    assert after["frames_dropped"] == before["frames_dropped"]
    assert get(base + "/cameras/a/latest.jpg")[0] == 200


def test_with_curve_the_dashboard_uses_the_services_own_pair(start_service, wait, keys):
    """Issue 33, finding 12: the allowed clients' folder holds alice's key only, not the
    service's; the coordinator lets the service's own pair in, so its dashboard connects."""
    folder, allowed = keys
    assert os.listdir(allowed) == ["alice.key"]
    port = free_tcp_port()
    start_service(
        *CAMERAS,
        "--curve-secret",
        str(folder / "server.key_secret"),
        "--curve-clients",
        str(allowed),
        client_keys=client_keys(folder, "alice"),
        http=f"127.0.0.1:{port}",
    )
    base = f"http://127.0.0.1:{port}"
    wait(lambda: service_ok(base), timeout=30, what="the dashboard served through CurveZMQ")
    assert get(base + "/cameras/a/latest.jpg")[0] == 200
