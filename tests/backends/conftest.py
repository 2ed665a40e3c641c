"""Fixtures for backend tests against real protocol peers: GigE Vision camera
emulators (``arv-fake-gv-camera-0.8``) started per test and killed at teardown,
a second loopback address for a second emulator, and real ``fxis run`` services.

Nothing is skipped: where Aravis' Python binding or the emulator is missing the tests
fail saying what to install (`make test` installs both).
"""

from __future__ import annotations

import itertools
import os
import shutil
import signal
import socket
import struct
import subprocess
import time

import pytest

from fxis_shm.service.tether import die_with_parent
from fxis_shm.shm import procstat
from fxis_shm.wire.gvcp_action import GVCP_PORT

from ..conftest import fxis, start_service  # noqa: F401  (shared with the integration tests)
from ..hosts import loopback_address

EMULATOR = "arv-fake-gv-camera-0.8"
# how Aravis marks a warning's and an error's line in its log
WARNING, ERROR = "\N{NEGATIVE SQUARED LATIN CAPITAL LETTER W}", "\N{NEGATIVE SQUARED LATIN CAPITAL LETTER E}"
SECOND_ADDRESS = "127.0.0.2"
START_TIMEOUT_S = 10.0


def aravis_missing() -> str | None:
    """Why the Aravis tests cannot run here, or None."""
    if shutil.which(EMULATOR) is None:
        return f"{EMULATOR} is not installed (Debian package aravis-tools)"
    try:
        from fxis_shm.workers.backends.aravis_library import load_aravis

        load_aravis()
    except ImportError as exc:
        return str(exc)
    return None


@pytest.fixture(scope="session")
def aravis_available():
    reason = aravis_missing()
    if reason:
        pytest.fail(f"{reason}; `make test` installs what the Aravis tests need")


# ---- a GigE Vision control-channel probe, without Aravis --------------------------------------

_request_ids = itertools.count(1)


def gvcp_serial(address: str, timeout: float = 0.2) -> str | None:
    """The serial number of the GigE Vision device answering on ``address`` (a
    READMEM of the bootstrap serial-number register), or None if none answers."""
    req_id = next(_request_ids) % 0xFFFF + 1
    # header: key 0x42, flags (ack required), READMEM_CMD 0x0084, payload length, request id;
    # payload: address 0x00D8 (serial number), reserved, count 16
    packet = struct.pack(">BBHHHIHH", 0x42, 0x01, 0x0084, 8, req_id, 0x00D8, 0, 16)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(timeout)
        try:
            sock.sendto(packet, (address, GVCP_PORT))
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                reply = sock.recv(1024)
                status, answer, _, ack_id = struct.unpack(">HHHH", reply[:8])
                if answer == 0x0085 and ack_id == req_id and status == 0:
                    return reply[12:28].split(b"\0")[0].decode(errors="replace")
        except (TimeoutError, ConnectionRefusedError, OSError):
            return None
    return None


class Emulator:
    """One ``arv-fake-gv-camera-0.8`` process: a GigE Vision camera on ``address``."""

    def __init__(
        self,
        address: str,
        serial: str,
        loss_per_thousand: int = 0,
        log_path: str | None = None,
        debug: str = "device:1",
    ):
        self.address, self.serial, self.loss = address, serial, loss_per_thousand
        self.log_path, self.debug = log_path, debug
        self.proc: subprocess.Popen | None = None

    @property
    def device_id(self) -> str:
        """The id Aravis gives it (what `fxis cameras` lists and device=... takes)."""
        return f"Aravis-Fake-{self.serial}"

    def start(self) -> Emulator:
        other = gvcp_serial(self.address)
        if other is not None:
            raise RuntimeError(
                f"a GigE Vision device (serial {other!r}) already answers on "
                f"{self.address}:{GVCP_PORT}; a leftover emulator? stop it first"
            )
        args = [EMULATOR, "-i", self.address, "-s", self.serial]
        if self.loss:
            args += ["-r", str(self.loss)]
        log = open(self.log_path, "ab") if self.log_path else subprocess.DEVNULL
        # its warnings in the log: a command it ignored says why ("not controller", "Heartbeat timeout");
        # device:3 adds each control command it handled, with its time
        env = {**os.environ, "ARV_DEBUG": self.debug}
        try:
            self.proc = subprocess.Popen(
                args, stdout=log, stderr=log, stdin=subprocess.DEVNULL, preexec_fn=die_with_parent, env=env
            )
        finally:
            if self.log_path:
                log.close()
        deadline = time.monotonic() + START_TIMEOUT_S
        while gvcp_serial(self.address) != self.serial:
            if self.proc.poll() is not None:
                raise RuntimeError(f"{EMULATOR} {' '.join(args[1:])} exited with code {self.proc.returncode}")
            if time.monotonic() > deadline:
                self.kill()
                raise RuntimeError(f"{EMULATOR} on {self.address} did not answer within {START_TIMEOUT_S} s")
            time.sleep(0.02)
        return self

    def warnings(self) -> list[str]:
        """The warnings and errors the emulator logged so far (Aravis marks their lines)."""
        return [line for line in self.log() if WARNING in line or ERROR in line]

    def log(self) -> list[str]:
        """Every line the emulator logged so far (what ARV_DEBUG above lets through)."""
        if not self.log_path or not os.path.exists(self.log_path):
            return []
        with open(self.log_path, errors="replace") as log:
            return [line.rstrip() for line in log if line.strip()]

    def scheduling(self) -> dict:
        """The emulator's state (R running, S sleeping, T stopped), and over its threads the CPU
        time it had and the time it waited, runnable, for a CPU (s): a camera that did not answer
        was either starved (waited grows), stopped, or given the CPU and silent."""
        stat = procstat.read(self.proc.pid) if self.proc is not None else None
        if stat is None:
            return {"state": "gone"}
        ran = waited = 0
        try:
            for task in os.listdir(f"/proc/{stat.pid}/task"):
                with open(f"/proc/{stat.pid}/task/{task}/schedstat") as schedstat:
                    cpu_ns, wait_ns, _ = (int(n) for n in schedstat.read().split())
                ran, waited = ran + cpu_ns, waited + wait_ns
        except (OSError, ValueError):
            return {"state": "gone"}
        return {"state": stat.state, "ran_s": round(ran / 1e9, 3), "waited_s": round(waited / 1e9, 3)}

    def kill(self) -> None:
        """SIGKILL: the camera vanishes as if unplugged."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(5)


@pytest.fixture(scope="session")
def second_address():
    """127.0.0.2 on lo for a second emulator."""
    with loopback_address(SECOND_ADDRESS) as address:
        yield address


_serials = itertools.count(1)


@pytest.fixture
def emulator(aravis_available, tmp_path):
    """Start emulators: ``emulator(address="127.0.0.1", loss_per_thousand=0)``; each gets
    a serial of its own (G, this process's id, then 01, 02, ... over the session: a pytest worker's
    camera must never share a device id with another worker's, which Aravis would open instead
    of the one a test killed) and is killed at teardown."""
    started: list[Emulator] = []

    def start(address: str = "127.0.0.1", loss_per_thousand: int = 0, debug: str = "device:1") -> Emulator:
        serial = f"G{os.getpid() % 100000:05d}{next(_serials):02d}"
        emu = Emulator(address, serial, loss_per_thousand, str(tmp_path / f"emulator-{serial}.log"), debug)
        started.append(emu)
        return emu.start()

    yield start
    for emu in started:
        emu.kill()
