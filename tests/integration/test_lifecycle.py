"""Start, stop, crash and clean-up of whole services (real processes and /dev/shm)."""

import os
import signal
import socket
import subprocess

import posix_ipc
import pytest

from fxis_shm import CameraDown
from fxis_shm.errors import ServiceNotStarted
from fxis_shm.service.launch import ServiceProcess
from fxis_shm.shm import naming

from ..conftest import assert_nothing_left, fxis
from .conftest import SMALL, child_pids

pytestmark = pytest.mark.integration


def test_stop_leaves_nothing_behind(start_service):
    svc = start_service("--camera", f"a=synthetic:{SMALL}")
    assert naming.leftovers(svc.name), "a running service has rings in /dev/shm"
    assert svc.stop() == 0
    assert_nothing_left(svc.name)


def test_sigint_stops_like_ctrl_c(start_service):
    svc = start_service("--camera", f"a=synthetic:{SMALL}")
    svc.proc.send_signal(signal.SIGINT)
    assert svc.proc.wait(10) == 0
    assert_nothing_left(svc.name)


def test_killed_camera_worker_fails_fast(start_service, wait):
    svc = start_service("--restart-limit", "0", "--camera", f"a=synthetic:{SMALL}", "--camera", f"b=synthetic:{SMALL}")
    with svc.client(timeout=5.0) as client:
        victim = client.status()["cameras"]["a"]["writer_pid"]
        os.kill(victim, signal.SIGKILL)
        wait(lambda: not client.status()["cameras"]["a"]["alive"], what="status to show camera a down")
        with pytest.raises(CameraDown, match="'a'"):
            client.image("a")
        with pytest.raises(CameraDown):
            client.tuple()
        with pytest.raises(CameraDown):
            client.latest(["a"])
        assert client.image("b").camera == "b"  # the other camera still serves
        assert client.tuple(["b"])["b"].frame_id >= 0


def test_restarted_camera_worker_has_a_new_generation(start_service, wait):
    svc = start_service("--camera", f"a=synthetic:{SMALL}")
    with svc.client(timeout=5.0) as client:
        first = client.status()["cameras"]["a"]
        os.kill(first["writer_pid"], signal.SIGKILL)
        wait(
            lambda: client.status()["cameras"]["a"].get("generation") == 2 and client.status()["cameras"]["a"]["alive"],
            what="the worker to come back",
        )
        frame = client.image("a")
        assert frame.generation == 2


def test_second_run_of_the_same_name_is_refused(start_service):
    svc = start_service("--camera", f"a=synthetic:{SMALL}")
    result = fxis(
        "run",
        "--name",
        svc.name,
        "--camera",
        f"a=synthetic:{SMALL}",
        "--endpoint",
        "tcp://127.0.0.1:0",
        "--pub",
        "tcp://127.0.0.1:1",
    )
    assert result.returncode == 2  # a setting to change: --name (docs/cli.md)
    assert "already running" in result.stderr
    with svc.client() as client:  # the first one is unharmed
        assert client.status()["cameras"]["a"]["alive"]


def test_leftovers_of_a_crashed_run_are_removed(start_service):
    name = f"crash{os.getpid()}"
    stale = posix_ipc.SharedMemory(f"/fxis.{name}.old.ring", posix_ipc.O_CREX, size=4096)
    stale.close_fd()
    posix_ipc.Semaphore(f"/fxis.{name}.old.new", posix_ipc.O_CREX).close()
    svc = start_service("--camera", f"a=synthetic:{SMALL}", name=name)
    assert all(".old." not in path for path in naming.leftovers(name))
    assert svc.stop() == 0


def test_kill_9_of_the_supervisor_then_run_again(start_service, wait, tmp_path):
    first = ServiceProcess(["--camera", f"a=synthetic:{SMALL}"], stderr=subprocess.DEVNULL).start()
    children = child_pids(first, "camera") + child_pids(first, "coordinator")
    first.proc.kill()
    first.proc.wait()
    # the children notice their parent died (PR_SET_PDEATHSIG) and exit
    wait(
        lambda: (
            not any(
                os.path.exists(f"/proc/{pid}/cmdline") and open(f"/proc/{pid}/cmdline", "rb").read() for pid in children
            )
        ),
        timeout=30,  # a loaded machine may take a while to schedule their exit
        what="orphaned children to exit",
    )
    second = start_service("--camera", f"a=synthetic:{SMALL}", name=first.name)
    with second.client() as client:
        assert client.image("a").generation >= 1


@pytest.mark.parametrize(
    "flag,named",
    [
        ("a=synthetic:fps=0", "fps"),
        ("a=synthetic:pixel_format=yuv", "pixel_format"),
        ("a=warp", "warp"),
        ("a=synthetic:colour=red", "colour"),
        ("bad name=synthetic", "camera name"),
    ],
)
def test_bad_settings_exit_2_naming_the_setting(flag, named):
    result = fxis("run", "--camera", flag)
    assert result.returncode == 2
    assert named in result.stderr


def test_bad_config_file_exits_2(tmp_path):
    config = tmp_path / "bad.toml"
    config.write_text('slots = 1\n[cameras.a]\nkind = "synthetic"\n')
    result = fxis("run", "--config", str(config))
    assert result.returncode == 2 and "slots" in result.stderr


def test_config_file_is_used(start_service, tmp_path):
    config = tmp_path / "cell.toml"
    config.write_text(
        'slots = 5\n[cameras.left]\nkind = "synthetic"\nfps = 40\nwidth = 64\n'
        'height = 48\n[cameras.right]\nkind = "synthetic"\npixel_format = "bgr8"\n'
        "width = 64\nheight = 48\n"
    )
    svc = start_service("--config", str(config))
    with svc.client() as client:
        status = client.status()["cameras"]
        frames = client.tuple()
    assert set(status) == {"left", "right"} and status["left"]["ring_slots"] == 5
    assert frames["right"].image.shape == (48, 64, 3)


def _taken(endpoint: str) -> socket.socket:
    """The endpoint's port bound by another (this test's) process, as a parallel test might."""
    holder = socket.socket()
    holder.bind(("127.0.0.1", int(endpoint.rsplit(":", 1)[1])))
    holder.listen()
    return holder


def test_a_launcher_whose_drawn_port_was_taken_first_draws_again():
    svc = ServiceProcess(["--camera", f"a=synthetic:{SMALL}"])
    taken = svc.endpoint
    with _taken(taken), svc:
        assert svc.endpoint != taken
        with svc.client() as client:
            assert set(client.status()["cameras"]) == {"a"}


def test_a_launcher_given_a_port_in_use_stops_at_once():
    svc = ServiceProcess(["--camera", f"a=synthetic:{SMALL}"])
    given = ServiceProcess([], endpoint=svc.endpoint, name=svc.name + "g")
    with _taken(svc.endpoint), pytest.raises(ServiceNotStarted, match="exited with code 2"):
        given.start()
    assert given.endpoint == svc.endpoint
