"""Run a whole service (``fxis run``) as a child process, for tests, benchmarks
and scripts: ready when it answers ``status``, stopped with SIGTERM on exit.

    with ServiceProcess(["--camera", "a=synthetic"], name="demo") as svc:
        with svc.client() as c:
            c.tuple()
"""

from __future__ import annotations

import collections
import json
import os
import random
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import IO

from fxis_shm.client.client import Client
from fxis_shm.errors import RequestTimeout, ServiceNotStarted
from fxis_shm.service.tether import die_with_parent
from fxis_shm.shm import naming, procstat
from fxis_shm.wire.security import ClientKeys


def free_tcp_ports(count: int) -> list[int]:
    """``count`` distinct ports of ``free_tcp_port``."""
    ports: list[int] = []
    while len(ports) < count:
        port = free_tcp_port()
        if port not in ports:
            ports.append(port)
    return ports


def free_tcp_port() -> int:
    """A TCP port free on every interface now, drawn below the kernel's ephemeral range: the
    ports the kernel gives outgoing connections (ZeroMQ's, a browser's) are drawn from that
    range, so none of them can take this one before the caller binds it (a port the kernel
    chose for a bind to port 0 could be). Drawn from this process's part of that span
    (``draw_from_part``), and not one it drew lately (its service may not have bound it yet)."""
    low, high = _part_bounds()
    for _ in range(500):
        port = _DRAW.randrange(low, high)
        if port in _recent:
            continue
        with socket.socket() as s:
            try:
                s.bind(("", port))
            except OSError:  # in use (or in TIME_WAIT): another
                continue
        _recent.append(port)
        return port
    with socket.socket() as s:  # that part of the range is taken: let the kernel choose
        s.bind(("127.0.0.1", 0))
        chosen: int = s.getsockname()[1]
        return chosen


_SPAN = 12_000  # ports drawn from, just below the ephemeral range
_part = (0, 1)  # which part of the span this process draws from: (index, parts)
_recent: collections.deque[int] = collections.deque(maxlen=256)  # drawn by this process lately


def draw_from_part(index: int, parts: int) -> None:
    """This process draws its ports from part ``index`` of ``parts`` equal parts of the span.
    Processes that launch services at once (a test suite's workers) each take a part of their
    own: a port one of them drew is free until its service binds it, and another drawing from
    the whole span could draw it meanwhile (make test runs 38, 51, 54)."""
    if not 0 <= index < parts:
        raise ValueError(f"part {index} of {parts}: expected 0 <= index < parts")
    global _part
    _part = (index, parts)


def _part_bounds() -> tuple[int, int]:
    """[low, high) of this process's part of the span."""
    below = _ephemeral_start()
    low = max(1024, below - _SPAN)
    index, parts = _part
    width = (below - low) // parts
    return low + index * width, low + (index + 1) * width


_PORT_DRAWS = 3  # starts of a service whose drawn port another process took first


def _bindable(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("", port))
        except OSError:
            return False
        return True


_DRAW = random.Random()  # its own: a test that seeds the module's generator must not make ports repeat


def _ephemeral_start() -> int:
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768  # Linux's default


class ServiceProcess:
    def __init__(
        self,
        args: Sequence[str] = (),
        name: str | None = None,
        endpoint: str | None = None,
        pub: str | None = None,
        events: str | None = None,
        ready_timeout: float = 30.0,
        stderr: int | IO[str] | IO[bytes] | None = None,
        client_keys: ClientKeys | None = None,
        python: str = sys.executable,
        env: dict[str, str] | None = None,
        wrapper: Sequence[str] = (),
        http: str = "off",
    ):
        """``http``: the dashboard's HOST:PORT, or "off" (the default: tests and scripts
        running at once must not all claim the same fixed port)."""
        self.name = name or f"t{os.getpid()}x{time.monotonic_ns() % 10**6}"
        # the endpoints not given are drawn here: free now, but another process may bind one of
        # them before the service does (start draws them again then)
        self._drawn = [key for key, given in (("endpoint", endpoint), ("pub", pub), ("events", events)) if not given]
        ports = free_tcp_ports(3)  # three distinct: two random draws can be the same port
        self.endpoint = endpoint or f"tcp://127.0.0.1:{ports[0]}"
        self.pub = pub or f"tcp://127.0.0.1:{ports[1]}"
        self.events = events or f"tcp://127.0.0.1:{ports[2]}"
        self.extra_args = list(args)
        self.http = http
        self.ready_timeout = ready_timeout
        self.stderr = stderr
        self.client_keys = client_keys  # for a service with CurveZMQ
        self.python, self.env = python, env  # the interpreter and environment of `fxis run`
        # a command that runs the service (e.g. in other namespaces: tests/hosts.py); it must
        # exec it, not fork, so that SIGTERM reaches the service
        self.wrapper = list(wrapper)
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def args(self) -> list[str]:
        """``fxis run``'s arguments."""
        names = ["--name", self.name, "--endpoint", self.endpoint, "--pub", self.pub, "--events", self.events]
        return [*names, "--http", self.http, *self.extra_args]

    def start(self) -> ServiceProcess:
        for _ in range(_PORT_DRAWS - 1):
            try:
                return self._start_once()
            except ServiceNotStarted as exc:
                if not self._drew_a_taken_port(str(exc)):
                    raise
        return self._start_once()

    def _drew_a_taken_port(self, said: str) -> bool:
        """Whether a port this launcher drew was taken (another process bound it first: the
        service stopped on it, saying so, or it is taken now); if so, those drawn are drawn
        again. Taken now is not enough: another process may have held it only for a moment."""
        drawn = {key: int(getattr(self, key).rsplit(":", 1)[1]) for key in self._drawn}
        if not any(f"port {port} is in use" in said or not _bindable(port) for port in drawn.values()):
            return False
        for key, port in zip(drawn, free_tcp_ports(len(drawn))):
            setattr(self, key, f"tcp://127.0.0.1:{port}")
        return True

    def _start_once(self) -> ServiceProcess:
        self.proc = subprocess.Popen(
            [*self.wrapper, self.python, "-m", "fxis_shm.cli", "run", *self.args],
            env=self.env,
            stdout=subprocess.DEVNULL,
            stderr=self.stderr,
            stdin=subprocess.DEVNULL,
            preexec_fn=die_with_parent,  # a killed launcher takes its service along
        )
        deadline = time.monotonic() + self.ready_timeout
        with self.client(timeout=0.5) as client:
            while True:
                if self.proc.poll() is not None:
                    code = self.proc.returncode
                    raise ServiceNotStarted(f"fxis run exited with code {code} during start-up{self.said()}")
                try:
                    client.status()
                    return self
                except RequestTimeout:
                    if time.monotonic() > deadline:
                        self.stop()
                        said = self.said()
                        raise ServiceNotStarted(f"service did not answer within {self.ready_timeout} s{said}") from None

    def said(self) -> str:
        """The end of what the service wrote to ``stderr``, when that is a file: the why of a failed start."""
        log = self.stderr
        name = getattr(log, "name", None)
        if log is None or isinstance(log, int) or not isinstance(name, str) or not os.path.isfile(name):
            return ""
        log.flush()
        with open(name, errors="replace") as f:
            said = f.read()[-3000:].strip()
        return f"; it said:\n{said}" if said else ""

    def client(self, timeout: float = 2.0) -> Client:
        return Client(self.endpoint, timeout=timeout, keys=self.client_keys)

    def children(self, state: str | None = None) -> dict[str, int]:
        """The service's running child processes by the supervisor's name for them (``camera:NAME``,
        ``coordinator``, ``dashboard``, ...) -> pid, from its process table: a forked worker's
        command line is the supervisor's, so ``ps`` cannot tell them apart by it. ``state``: only
        those the table says are in it (``"running"``: ready; a child is listed from its start on)."""
        try:
            with open(naming.supervisor_state_path(self.name)) as f:
                processes = json.load(f)["processes"]
        except (OSError, ValueError, KeyError):
            return {}
        children = procstat.children(self.proc.pid) if self.proc else []
        running = {child.pid for child in children if child.running}  # not a killed one not yet reaped
        return {
            key: p["pid"] for key, p in processes.items() if p.get("pid") in running and state in (None, p.get("state"))
        }

    def stop(self, timeout: float = 10.0) -> int:
        """SIGTERM, wait, then kill; returns the exit code."""
        if self.proc is None:
            return 0
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode

    def __enter__(self) -> ServiceProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
