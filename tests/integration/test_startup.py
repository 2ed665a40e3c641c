"""Everything a newcomer meets when starting a service or talking to one: every address is
checked before anything starts, a port in use is one line and exit code 2, one base moves
every port, and a command against a CurveZMQ service takes keys and says when they are
what is missing."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from contextlib import contextmanager

import pytest

from fxis_shm import Client, RequestTimeout
from fxis_shm.errors import ConfigError, ServiceNotStarted
from fxis_shm.service.addresses import check_free
from fxis_shm.service.config import HTTP_OFF, build_config
from fxis_shm.service.launch import ServiceProcess, free_tcp_port
from fxis_shm.shm import naming
from fxis_shm.wire import defaults

from ..conftest import assert_nothing_left, fxis, fxis_run_alone, wait_until
from .conftest import SMALL, client_keys

pytestmark = pytest.mark.integration


@contextmanager
def listening(port: int | None = None):
    """A port some other program holds (listening, as a running service's would be)."""
    with socket.socket() as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("127.0.0.1", port or 0))
        sock.listen()
        yield sock.getsockname()[1]


@pytest.mark.parametrize("option", ["--endpoint", "--pub", "--events", "--http", "--foxglove"])
def test_a_port_in_use_stops_the_start_before_anything_runs(option):
    with listening() as port:
        address = f"tcp://127.0.0.1:{port}" if option in ("--endpoint", "--pub", "--events") else f"127.0.0.1:{port}"
        name = f"busy{port}"
        result = fxis_run_alone("--name", name, option, address, "--camera", f"a=synthetic:{SMALL}")
    assert result.returncode == 2
    (line,) = result.stderr.strip().splitlines()  # one line, no traceback
    assert option in line and str(port) in line and "in use" in line and "--port-base" in line
    assert naming.leftovers(name) == []  # no camera worker was started


def test_a_launcher_whose_drawn_port_another_process_held_for_a_moment_draws_again(tmp_path):
    """The service stopped on a drawn port another process bound first; by the time the
    launcher looks, that process let it go (make test: another test's service, port 30577). The
    service's own line says the port was taken: the launcher draws again."""
    with open(tmp_path / "service.log", "w") as log:
        svc = ServiceProcess(["--camera", f"a=synthetic:{SMALL}"], stderr=log)
        # the port the service checks first: any other drawn port may be taken meanwhile by another
        # test's service, as here (make test run 51: its --pub), and the service names the first taken
        endpoint = int(svc.endpoint.rsplit(":", 1)[1])
        with listening(endpoint):
            with pytest.raises(ServiceNotStarted, match=f"port {endpoint} is in use") as stopped:
                svc._start_once()
        assert svc._drew_a_taken_port(str(stopped.value))  # free again now, and yet drawn again
        assert svc.endpoint != f"tcp://127.0.0.1:{endpoint}"
        try:
            svc.start()
        finally:
            svc.stop()


def test_an_endpoint_without_a_port_is_refused_with_what_it_needs():
    result = fxis_run_alone("--endpoint", "tcp://127.0.0.1")
    assert result.returncode == 2
    assert "expected tcp://HOST:PORT with a port" in result.stderr and "Traceback" not in result.stderr


def test_the_dashboard_on_its_default_address_gives_way_to_a_program_holding_that_port():
    zmq_endpoints = {"endpoint": free_endpoint(), "pub": free_endpoint(), "events": free_endpoint()}
    port = int(defaults.HTTP.rsplit(":", 1)[1])
    with occupied(port):
        config, warnings = check_free(build_config(zmq_endpoints))  # the dashboard nobody asked for
        assert config.http == HTTP_OFF and "default address" in warnings[0] and "--http" in warnings[0]
        with pytest.raises(ConfigError, match="--http"):  # asked for explicitly: refused, not dropped
            check_free(build_config({**zmq_endpoints, "http": defaults.HTTP}))


@contextmanager
def occupied(port: int):
    """``port`` in use: held here, or already by some other program."""
    try:
        with listening(port):
            yield
    except OSError:
        yield


def free_endpoint() -> str:
    return f"tcp://127.0.0.1:{free_tcp_port()}"


def free_block(size: int = 4) -> int:
    """A first port of ``size`` free ports in a row."""
    for _ in range(50):
        base = free_tcp_port()
        if base + size > 65535:
            continue
        try:
            with listening(base), listening(base + 1), listening(base + 2), listening(base + 3):
                return base
        except OSError:
            continue
    raise AssertionError(f"no {size} free ports in a row")


def test_port_base_moves_every_port_and_clients_find_the_service_there():
    base = free_block()
    config = build_config({"port_base": base})
    assert (config.endpoint, config.pub, config.events) == tuple(f"tcp://127.0.0.1:{base + i}" for i in range(3))
    assert config.http == f"127.0.0.1:{base + 3}"
    assert build_config({"port_base": base, "pub": "tcp://127.0.0.1:7"}).pub == "tcp://127.0.0.1:7"  # given wins
    name = f"based{base}"
    run = [sys.executable, "-m", "fxis_shm.cli", "run", "--name", name, "--port-base", str(base), "--http", "off"]
    service = subprocess.Popen([*run, "--camera", f"a=synthetic:{SMALL}"], stderr=subprocess.DEVNULL)
    try:
        with Client(f"tcp://127.0.0.1:{base}", timeout=1.0) as client:
            status = wait_until(lambda: answered(client), timeout=30, what="the service on the port base")
        assert status["pub"] == f"tcp://127.0.0.1:{base + 1}" and status["events"] == f"tcp://127.0.0.1:{base + 2}"
        assert status["service"] == name
    finally:
        service.terminate()
        service.wait(timeout=30)
    assert_nothing_left(name)


def answered(client: Client) -> dict | None:
    try:
        return client.status()
    except RequestTimeout:
        return None


def test_a_client_without_keys_is_told_the_service_wants_curvezmq(curve_service):
    svc, folder = curve_service
    with Client(svc.endpoint, timeout=3.0) as stranger, pytest.raises(RequestTimeout) as info:
        stranger.status()
    assert "answers only CurveZMQ" in str(info.value) and "--server-key" in str(info.value)
    with Client(svc.endpoint, timeout=3.0, keys=client_keys(folder, "mallory")) as mallory:
        with pytest.raises(RequestTimeout) as info:
            mallory.status()
    assert "refused this client's key" in str(info.value) or "handshake" in str(info.value)


def test_status_grab_and_record_take_keys_from_flags_the_environment_or_the_config(curve_service, tmp_path):
    svc, folder = curve_service
    server, alice = str(folder / "server.key"), str(folder / "alice.key_secret")
    keyless = fxis("status", "--endpoint", svc.endpoint, "--timeout", "3")
    assert keyless.returncode == 3 and "answers only CurveZMQ" in keyless.stderr
    flags = fxis("status", "--endpoint", svc.endpoint, "--server-key", server, "--client-key", alice, "--json")
    assert flags.returncode == 0 and json.loads(flags.stdout)["service"] == svc.name
    env = {"FXIS_SERVER_KEY": server, "FXIS_CLIENT_KEY": alice}
    grabbed = subprocess.run(
        [sys.executable, "-m", "fxis_shm.cli", "grab", "--endpoint", svc.endpoint, "--out", str(tmp_path / "g")],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, **env},
    )
    assert grabbed.returncode == 0, grabbed.stderr
    assert (tmp_path / "g" / "tuple.json").exists()
    config = tmp_path / "cell.toml"
    config.write_text(f'endpoint = "{svc.endpoint}"\n[client]\nserver_key = "{server}"\nclient_key = "{alice}"\n')
    recorded = fxis("record", "--config", str(config), "--out", str(tmp_path / "bag"), "--frames", "3")
    assert recorded.returncode == 0, recorded.stderr
    half = fxis("status", "--endpoint", svc.endpoint, "--server-key", server)
    assert half.returncode == 2 and "--client-key" in half.stderr


def test_a_clean_start_and_a_restart_log_no_unreachable_worker(start_service, tmp_path):
    """Issue 43: at every start the log said "camera X did not report its settings ... its
    worker is not running" just after that worker said it streams: the coordinator asked the
    moment it had called connect(), before ZeroMQ had linked it (ZMQ_IMMEDIATE fails such a
    send). It now asks when the link is up, at start and after a worker's restart, so status
    has every camera's settings without anyone asking, and the log says nothing of the kind."""
    import signal

    svc = start_service("--camera", f"a=synthetic:{SMALL}", "--camera", f"b=synthetic:fps=10,{SMALL}")
    with svc.client() as client:
        wait_until(
            lambda: all(c.get("settings") for c in client.status()["cameras"].values()),
            timeout=10,
            what="every camera's settings in status (asked by the coordinator itself)",
        )
        generation = client.status()["cameras"]["a"]["generation"]
        os.kill(svc.children()["camera:a"], signal.SIGKILL)
        wait_until(
            lambda: (
                (a := client.status()["cameras"]["a"]).get("generation", generation) > generation and a.get("settings")
            ),
            timeout=20,
            what="camera a's settings of its new generation, after its restart",
        )
    svc.stop()
    log = (tmp_path / "service0.log").read_text()
    assert log.count("streaming") >= 3, log  # a, b and a again: the workers did start
    assert "did not report its settings" not in log and "not running" not in log, log
