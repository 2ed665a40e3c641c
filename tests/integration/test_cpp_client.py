"""examples/cpp_client/, the C++ client written from docs/protocol.md: built with g++ against
Debian's libzmq3-dev, cppzmq-dev and nlohmann-json3-dev, then run against live services.

The client keeps time in CLOCK_REALTIME while the service runs on CLOCK_MONOTONIC, so its
tuples at t* depend on its clock mapping (the protocol's `time` exchange) being right: the
test knows both clocks of this host and checks the mapping, the t* of each tuple, the frames
chosen for it and the frame-id stamp of every image.
"""

from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path

import pytest

from fxis_shm.core import timebase
from fxis_shm.service.launch import ServiceProcess

from .conftest import SMALL, client_keys, module_service

pytestmark = pytest.mark.integration

SOURCE = Path(__file__).resolve().parents[2] / "examples" / "cpp_client"
FPS = 50
PERIOD_NS = 1_000_000_000 // FPS
# (Debian package, what in it the build uses, a C++ include that shows it is there or None)
NEEDED = [
    ("g++", "the C++ compiler", None),
    ("make", "make", None),
    ("libzmq3-dev", "libzmq's header zmq.h and libzmq.so", "zmq.h"),
    ("cppzmq-dev", "cppzmq's header zmq.hpp", "zmq.hpp"),
    ("nlohmann-json3-dev", "nlohmann/json.hpp", "nlohmann/json.hpp"),
]


def _missing_packages() -> list[str]:
    missing = []
    for package, what, header in NEEDED:
        if header is None:
            if shutil.which(package) is None:
                missing.append(f"{package} ({what})")
            continue
        if shutil.which("g++") is None:
            missing.append(f"{package} ({what}; not checked without g++)")
            continue
        probe = subprocess.run(
            ["g++", "-std=c++17", "-E", "-x", "c++", "-", "-o", "/dev/null"],
            input=f"#include <{header}>\n",
            capture_output=True,
            text=True,
            timeout=60,
        )
        if probe.returncode != 0:
            missing.append(f"{package} ({what})")
    return missing


@pytest.fixture(scope="module")
def client_binary(tmp_path_factory) -> Path:
    """fxis_cpp_client built by the example's own Makefile into a temporary folder."""
    missing = _missing_packages()
    if missing:
        pytest.fail(
            "the C++ client cannot be built; missing Debian packages: "
            + ", ".join(missing)
            + ". scripts/install-system-packages.sh installs them (make setup runs it).",
            pytrace=False,
        )
    build = tmp_path_factory.mktemp("cpp_client")
    result = subprocess.run(
        ["make", "-C", str(SOURCE), f"BUILD_DIR={build}", "EXTRA_CXXFLAGS=-Werror"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, f"building examples/cpp_client failed:\n{result.stdout}\n{result.stderr}"
    binary = build / "fxis_cpp_client"
    assert binary.is_file(), f"make did not produce {binary}:\n{result.stdout}"
    return binary


@pytest.fixture(scope="module")
def cameras():
    # 2 s of history: a moment 200 ms before the client started is still held however long the
    # client takes to start and exchange its clock on a loaded machine (400 ms once, and a ring of
    # 0.4 s had moved on)
    yield from module_service(
        [
            "--history",
            "2",
            "--camera",
            f"cam0=synthetic:fps={FPS},{SMALL}",
            "--camera",
            f"cam1=synthetic:fps={FPS},phase_ms=1,{SMALL}",
        ]
    )


def run_client(binary: Path, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([str(binary), *args], capture_output=True, text=True, timeout=timeout)


def parse(stdout: str) -> list[tuple[str, dict[str, str]]]:
    """The client's lines: (kind, {key: value})."""
    lines = []
    for line in stdout.splitlines():
        kind, *pairs = line.split()
        lines.append((kind, dict(pair.split("=", 1) for pair in pairs)))
    return lines


def wait_for_history(svc: ServiceProcess, seconds: float) -> None:
    """Until every ring holds ``seconds`` of frames (a past t* must be in them)."""
    deadline = time.monotonic() + 20
    with svc.client() as client:
        while True:
            status = client.status()
            if all(c.get("frames_stored", 0) >= seconds * FPS + 2 for c in status["cameras"].values()):
                return
            assert time.monotonic() < deadline, f"the rings did not fill within 20 s: {status['cameras']}"
            time.sleep(0.05)


def test_tuples_at_times_of_the_clients_own_clock(client_binary, cameras):
    wait_for_history(cameras, 0.3)
    asked_now = time.time_ns()
    past, future = asked_now - 200_000_000, asked_now + 300_000_000
    result = run_client(
        client_binary,
        *("--endpoint", cameras.endpoint, "--clock", "realtime"),
        *("--at", str(past), "--at", "now", "--at", str(future)),
    )
    done = time.time_ns()
    true_offset = timebase.offset("monotonic", "realtime")  # service clock minus the client's, read here
    assert result.returncode == 0, f"fxis_cpp_client exited {result.returncode}:\n{result.stdout}\n{result.stderr}"
    lines = parse(result.stdout)

    kind, clock = lines[0]
    assert kind == "clock" and clock["ours"] == "CLOCK_REALTIME" and clock["service"] == "CLOCK_MONOTONIC", lines[0]
    assert int(clock["exchanges"]) == 8
    # an NTP estimate is off by at most half its round trip; 2 ms more for the host clocks slewing meanwhile
    bound = int(clock["round_trip_ns"]) // 2 + 2_000_000
    assert abs(int(clock["offset_ns"]) - true_offset) <= bound, (
        f"the client's clock offset {clock['offset_ns']} ns is not the true {true_offset} ns within {bound} ns"
    )

    tuples = [i for i, (kind, _) in enumerate(lines) if kind == "tuple"]
    assert len(tuples) == 3, result.stdout
    for start, asked in zip(tuples, (past, None, future)):
        t_request = int(lines[start][1]["t_request"])
        if asked is None:  # "now": the moment of the call, in the client's clock
            assert asked_now <= t_request <= done, f"t* of 'now' {t_request} is not within the client's run"
        else:
            assert t_request == asked, f"asked for t* {asked}, the tuple says {t_request}"
        frames = {values["camera"]: values for kind, values in lines[start + 1 : start + 3]}
        assert set(frames) == {"cam0", "cam1"}, result.stdout
        for name, frame in frames.items():
            assert frame["stamp_ok"] == "yes" and frame["stamp"] == frame["frame_id"], (
                f"{name}: the pixels carry stamp {frame['stamp']}, the metadata frame {frame['frame_id']}"
            )
            t_capture, t_service = int(frame["t_capture"]), int(frame["t_capture_service"])
            assert abs(t_capture - (t_service - true_offset)) <= bound, (
                f"{name}: t_capture {t_capture} in the client's clock is not the service's {t_service} moved by the"
                f" true offset"
            )
            if asked == past:  # its frames were stored long before: the nearest, within a period
                assert abs(t_capture - t_request) <= PERIOD_NS + 2_000_000, (
                    f"{name}: frame captured {(t_capture - t_request) / 1e6:.1f} ms from t*"
                )
            else:  # "now" and the future wait for frames to come, and a held-up worker's is taken for
                # dropped after a period and its delay (make test run 43: a frame 113 ms before "now")
                assert t_capture <= done, f"{name}: frame captured after the client's run"
            assert frame["shape"] == "48x64" and frame["dtype"] == "uint8"
        assert abs(int(frames["cam0"]["t_capture"]) - int(frames["cam1"]["t_capture"])) <= 2_000_000


def test_errors_are_reported_with_their_code(client_binary, cameras):
    result = run_client(client_binary, "--endpoint", cameras.endpoint, "--cameras", "cam0,nowhere")
    assert result.returncode == 3, result.stdout + result.stderr
    assert "UNKNOWN_CAMERA" in result.stderr and "nowhere" in result.stderr


def test_curve_keys_from_fxis_keys_files(client_binary, start_service, keys):
    folder, allowed = keys
    svc = start_service(
        "--camera",
        f"a=synthetic:fps={FPS},{SMALL}",
        "--curve-secret",
        str(folder / "server.key_secret"),
        "--curve-clients",
        str(allowed),
        client_keys=client_keys(folder, "alice"),
    )
    server = str(folder / "server.key")
    alice = run_client(
        client_binary,
        *("--endpoint", svc.endpoint, "--server-key", server, "--client-key", str(folder / "alice.key_secret")),
    )
    assert alice.returncode == 0, f"with allowed keys:\n{alice.stdout}\n{alice.stderr}"
    frame = [values for kind, values in parse(alice.stdout) if kind == "frame"]
    assert len(frame) == 1 and frame[0]["camera"] == "a" and frame[0]["stamp_ok"] == "yes", alice.stdout
    mallory = run_client(
        client_binary,
        *("--endpoint", svc.endpoint, "--server-key", server, "--client-key", str(folder / "mallory.key_secret")),
        *("--timeout-ms", "500"),
    )
    assert mallory.returncode == 3 and "keys" in mallory.stderr, f"refused keys:\n{mallory.stdout}\n{mallory.stderr}"
