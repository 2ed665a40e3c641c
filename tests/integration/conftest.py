import contextlib
import subprocess
import tempfile
import time

import pytest

from fxis_shm import Client
from fxis_shm.errors import OutOfRange
from fxis_shm.service.launch import ServiceProcess

from ..conftest import assert_nothing_left, start_service, wait_until  # noqa: F401  (shared fixtures)

# run by tests/integration/test_lerobot.py in the lerobot venv, never imported here (it imports lerobot)
collect_ignore = ["lerobot_reads.py"]

SMALL = "width=64,height=48"


def module_services(*arg_lists: list[str], **options):
    """Services shared by a module's tests that only read (yield from it in a module-scoped
    fixture): started once rather than once a test, each with ``options`` (ServiceProcess's).
    Each is stopped and checked for leftovers afterwards, also when a later one failed to start."""
    started: list[ServiceProcess] = []
    logs = []  # what each said: a failed start quotes it
    try:
        for args in arg_lists:
            logs.append(tempfile.NamedTemporaryFile("w", prefix="fxis-service-", suffix=".log"))
            started.append(ServiceProcess(args, stderr=logs[-1], **options))
            started[-1].start()
        yield started
    finally:
        for svc in started:
            svc.stop()
        for log in logs:
            log.close()
    for svc in started:
        assert_nothing_left(svc.name)


@pytest.fixture(scope="module")
def two_services(request):
    """The module's ``TWO_SERVICES`` (two argument lists), shared by its tests that only read
    from the services."""
    yield from module_services(*request.module.TWO_SERVICES)


@pytest.fixture
def two_services_to_stop(request, start_service):  # noqa: F811  (the fixture, by name)
    """The module's ``TWO_SERVICES``, a test's own, for the tests that stop a service's coordinator."""
    return [start_service(*args) for args in request.module.TWO_SERVICES]


def module_service(args: list[str]):
    """A service shared by a module's tests (yield from it in a module-scoped fixture)."""
    for (svc,) in module_services(args):
        yield svc


def module_service_with_full_rings(args: list[str]):
    """``module_service``, yielded once every camera's ring is full (as after a while): its
    history is all there."""
    for svc in module_service(args):
        with Client(svc.endpoint) as client:
            wait_until(
                lambda: all(c["frames_stored"] >= c["ring_slots"] for c in client.status()["cameras"].values()),
                timeout=20,
                what="full rings",
            )
        yield svc


@pytest.fixture(scope="module")
def two_cameras():
    """A shared service with two small synthetic cameras at 50 fps, for tests that only read."""
    yield from module_service(
        ["--camera", f"cam0=synthetic:fps=50,{SMALL}", "--camera", f"cam1=synthetic:fps=50,phase_ms=1,{SMALL}"]
    )


def child_pids(svc, role: str, state: str | None = None) -> list[int]:
    """Pids of the service's running children of one role ("camera" or "coordinator"); ``state``:
    only those the supervisor's table says are in it ("running": ready, not just started)."""
    return [pid for key, pid in svc.children(state).items() if key.split(":")[0] == role]


@pytest.fixture
def keys(tmp_path):
    """CurveZMQ key pairs made by `fxis keys`: server, alice (allowed in) and mallory (not)."""
    from ..conftest import fxis

    folder, allowed = tmp_path / "keys", tmp_path / "allowed"
    for name in ("server", "alice", "mallory"):
        assert fxis("keys", "--out", str(folder), "--name", name).returncode == 0
    allowed.mkdir()
    (allowed / "alice.key").write_bytes((folder / "alice.key").read_bytes())
    return folder, allowed


def client_keys(folder, name):
    from fxis_shm import ClientKeys

    return ClientKeys.from_files(str(folder / "server.key"), str(folder / f"{name}.key_secret"))


@contextlib.contextmanager
def mounted_tmpfs(mount, options: str):
    """A tmpfs mounted at ``mount`` (made here) with ``options`` (root), unmounted afterwards
    whatever happened."""
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(mount)], capture_output=True)
    if done.returncode != 0:
        pytest.fail(f"mounting a tmpfs needs root: {done.stderr.decode().strip()}", pytrace=False)
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=True)


@pytest.fixture
def small_disk(tmp_path):
    """An 8 MiB tmpfs mounted for the test."""
    with mounted_tmpfs(tmp_path / "disk", "size=8m") as mount:
        yield mount


@pytest.fixture
def curve_service(start_service, keys):  # noqa: F811  (the fixture, by name)
    """A service with CurveZMQ that lets alice in (not mallory), and the folder of the keys."""
    folder, allowed = keys
    svc = start_service(
        "--camera",
        f"a=synthetic:fps=50,{SMALL}",
        "--curve-secret",
        str(folder / "server.key_secret"),
        "--curve-clients",
        str(allowed),
        client_keys=client_keys(folder, "alice"),
    )
    return svc, folder


def streamed_and_asked(client, sub, camera: str, timeout: float = 10.0):
    """A frame of ``camera`` from the subscription ``sub``, and the frame ``client`` gets asking
    for its capture time. A frame streamed later than its ring still holds it (a loaded machine,
    a small test ring: OUT_OF_RANGE) gives way to the next one, until ``timeout``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        frame = sub.receive().frames[0]
        if frame.camera == camera:
            try:
                return frame, client.image(camera, at=frame.t_capture, wait="none")
            except OutOfRange:
                pass
    raise AssertionError(f"no frame of {camera} streamed within {timeout} s was still held when asked for")
