"""The supervisor behind ``fxis run``: starts the camera workers and the
coordinator, watches and restarts them, and cleans up everything on exit.

Start-up: take the service's lock (refuse if another supervisor holds it),
remove what a crashed earlier run left in /dev/shm, start every camera worker
and wait for its readiness handshake, then the coordinator. Shutdown: ask
(SIGTERM), wait, kill; then unlink every segment and semaphore of the service.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from typing import TextIO, TypedDict

from fxis_shm.core import timebase
from fxis_shm.core.restarts import gives_up, recent_crashes
from fxis_shm.errors import ConfigError, FxisError
from fxis_shm.service.addresses import remove_stale_ipc_files
from fxis_shm.service.changers import change_lines, dashboard_access, ros2_may_change
from fxis_shm.service.childspec import (
    CameraWorkerSpec,
    ChildSpec,
    CoordinatorSpec,
    DashboardSpec,
    FoxgloveSpec,
    Ros2Spec,
)
from fxis_shm.service.config import CameraSpec, ServiceConfig, http_address, viewer_accesses
from fxis_shm.service.forkstart import ForkedProcess, fork_child, fork_wanted
from fxis_shm.service.memory import ring_lines
from fxis_shm.service.servicelock import ServiceLock
from fxis_shm.service.stopsignals import StopSignals
from fxis_shm.service.viewertokens import ViewerAccess
from fxis_shm.shm import naming
from fxis_shm.wire.statusdoc import SupervisorEvent, SupervisorState

log = logging.getLogger("supervisor")

READY_TIMEOUT_S = 20.0
STOP_GRACE_S = 3.0
BACKOFF_FIRST_S, BACKOFF_MAX_S = 0.5, 10.0
STABLE_AFTER_S = 30.0  # a child that ran this long has its backoff reset


class StartError(FxisError):
    """A child could not start; the message says which and why."""


class StartRefused(StartError, ConfigError):
    """A child said what it could not use of what it was given (a setting the camera refuses, a
    file or device that is not there, a hook that does not load): a setting to change."""


class Child:
    """One supervised process and its restart bookkeeping."""

    def __init__(self, spec: ChildSpec, label: str, key: str, env: dict[str, str] | None = None):
        self.spec, self.label, self.key = spec, label, key
        self.env = env  # added to the supervisor's environment (a viewer's token: never on argv, ps shows it)
        self.state = "starting"
        self.last_exit: int | None = None
        self.proc: subprocess.Popen[bytes] | ForkedProcess | None = None
        self.restarts = 0
        self.crashes: list[float] = []  # when it exited, within the restart window (monotonic s)
        self.backoff = BACKOFF_FIRST_S
        self.restart_at: float | None = None
        self.started_at = 0.0
        self._ready_fd: int | None = None

    def start(self) -> None:
        read_fd, write_fd = os.pipe()
        try:
            if self.spec.FORKABLE and not self.env and fork_wanted():
                argv = [self.spec.to_json(), str(write_fd)]
                self.proc = fork_child(self.spec.MODULE, argv, write_fd, self.spec.TITLE)
            else:
                self.proc = subprocess.Popen(
                    self.spec.command(write_fd),
                    pass_fds=(write_fd,),
                    stdin=subprocess.DEVNULL,
                    env={**os.environ, **self.env} if self.env else None,
                )
        finally:
            os.close(write_fd)
        self._ready_fd = read_fd
        self.started_at = time.monotonic()
        self.restart_at = None

    def wait_ready(self, timeout: float = READY_TIMEOUT_S) -> None:
        """Block until the child's handshake; raise StartError if it failed or timed out."""
        import select

        fd, self._ready_fd = self._ready_fd, None
        if fd is None or self.proc is None:
            raise StartError(f"{self.label} was not started")
        try:
            ready, _, _ = select.select([fd], [], [], timeout)
            line = os.read(fd, 4096).decode(errors="replace").strip() if ready else ""
        finally:
            os.close(fd)
        if line == "ok":
            return
        if line.startswith("error "):
            raise StartRefused(f"{self.label}: {line[len('error ') :]}")
        if not ready:
            raise StartError(f"{self.label} did not become ready within {timeout:.0f} s")
        raise StartError(f"{self.label} exited during start-up (exit code {self.proc.wait(1)})")

    def exited(self) -> int | None:
        return None if self.proc is None else self.proc.poll()

    def terminate(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()


class CommonFields(TypedDict):
    """What every child's spec is told alike."""

    service: str
    log_level: str
    clock: str


class ViewerFields(CommonFields):
    """What every viewer's spec (fxis_shm.service.childspec.ViewerSpec) is told alike."""

    endpoint: str
    curve_secret: str | None
    cameras: dict[str, dict[str, object]]


def history_of(camera: CameraSpec, config: ServiceConfig) -> float | None:
    """The seconds a camera's ring holds: its own history= key, else the service's."""
    return camera.options.get("history") or config.history


def viewer_children(config: ServiceConfig, common: CommonFields, access: dict[str, ViewerAccess]) -> list[Child]:
    """The processes that show the cameras, clients of the service like any other: the live
    dashboard (fxis_shm.viewers.dashboard) and the Foxglove server (fxis_shm.viewers.foxglove_live), each
    when its address is not off and told its ``access`` (token, TLS), and the ROS 2 bridge
    (fxis_shm.ros2) when it is on."""
    viewer: ViewerFields = {
        "service": common["service"],
        "log_level": common["log_level"],
        "clock": common["clock"],
        "endpoint": config.endpoint,
        "curve_secret": config.curve_secret,
        "cameras": {c.name: {"kind": c.kind, "fps": c.options.get("fps")} for c in config.cameras},
    }
    children = []
    if config.http_url:
        children.append(
            Child(
                DashboardSpec(**viewer, http=config.http),
                "dashboard",
                "dashboard",
                dashboard_access(config, access["http"]).environment(),
            )
        )
    if config.foxglove_url:
        children.append(
            Child(
                FoxgloveSpec(**viewer, foxglove=config.foxglove, rate_hz=config.foxglove_rate),
                "foxglove",
                "foxglove",
                access["foxglove"].environment(),
            )
        )
    if config.ros2 is not None:
        cameras = {
            c.name: {
                **viewer["cameras"][c.name],
                "frame_id": c.options.get("frame_id") or c.name,
                "calibration": c.options.get("calibration"),
            }
            for c in config.cameras
        }
        ros2, bridge = config.ros2, viewer.copy()
        bridge["cameras"] = cameras
        spec = Ros2Spec(
            **bridge,
            domain=ros2.domain,
            namespace=ros2.namespace,
            tuples_hz=ros2.tuples_hz,
            snapshots=ros2.snapshots,
            via=ros2.via,
            python=ros2.python,
            may_change=ros2_may_change(config),
        )
        children.append(Child(spec, "ros2", key="ros2"))
    return children


def viewer_lines(config: ServiceConfig, access: dict[str, ViewerAccess]) -> list[str]:
    """The banner's lines of the dashboard and the Foxglove server: with a token, the address
    to open with it, as Jupyter prints it (the token itself only when it was made here)."""
    lines, unencrypted = [], False
    for setting, url in config.viewer_urls.items():
        if setting == "http":
            lines.append(f"  live dashboard on {url}/")
        else:
            lines.append(f"  Foxglove WebSocket server on {url} ({config.foxglove_rate:g} pictures/s per camera)")
        token = access[setting].token
        if token:
            shown = f"<the token in {config.viewer_token_file}>" if config.viewer_token_file else token
            scheme = url.split("://", 1)[0]
            lines[-1] += ", which requires a token: open"
            lines.append(f"      {scheme}://{link_host(getattr(config, setting), setting)}/?token={shown}")
            unencrypted |= url in config.exposed and not config.viewer_tls_cert
    if unencrypted:
        lines.append("  (no --viewer-tls-cert: the token and the pictures travel unencrypted)")
    return lines


def link_host(address: str, setting: str) -> str:
    """HOST:PORT to put in a link: a wildcard address (every interface) as this host's name."""
    host, port = http_address(address, setting)
    if host in ("0.0.0.0", "::", "*"):
        host = socket.gethostname()
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


class Supervisor:
    def __init__(self, config: ServiceConfig, out: TextIO = sys.stdout):
        self.config = config
        self.out = out
        self.stop: StopSignals | None = None  # from run() on: SIGINT or SIGTERM received
        origin = timebase.reader(config.clock)()  # the synthetic cameras' shared time origin
        common: CommonFields = {"service": config.name, "log_level": config.log_level, "clock": config.clock}
        realtime = config.realtime.priority if config.realtime else None  # viewers never: they are clients
        self.cameras = [
            Child(
                CameraWorkerSpec(
                    **common,
                    camera=c.name,
                    kind=c.kind,
                    options=c.options,
                    slots=config.slots,
                    time_origin_ns=origin,
                    history_s=history_of(c, config),
                    lockstep_hz=config.lockstep[0] if config.lockstep else None,
                    lockstep_phase_ns=config.lockstep[1] if config.lockstep else 0,
                    lockstep_clock=config.lockstep_clock,
                    realtime=realtime,
                ),
                f"camera {c.name!r}",
                key=f"camera:{c.name}",
            )
            for c in config.cameras
        ]
        self.coordinator = Child(
            CoordinatorSpec(
                **common,
                endpoint=config.endpoint,
                pub=config.pub,
                events=config.events,
                cameras={c.name: c.kind for c in config.cameras},
                settings=config.settings,
                curve_secret=config.curve_secret,
                curve_clients=config.curve_clients,
                curve_operators=config.curve_operators,
                history={c.name: h for c in config.cameras if (h := history_of(c, config))},
                realtime=realtime,
            ),
            "coordinator",
            key="coordinator",
        )
        self.viewer_access = viewer_accesses(config)  # the token, made or read once: restarts keep it
        self.viewers = viewer_children(config, common, self.viewer_access)
        self.events: list[SupervisorEvent] = []  # the latest exits and restarts, for status

    @property
    def children(self) -> list[Child]:
        return [*self.cameras, self.coordinator, *self.viewers]

    def run(self) -> int:
        """Serve until SIGINT/SIGTERM; returns the process exit code."""
        self.stop = StopSignals((signal.SIGINT, signal.SIGTERM))  # no thread: the supervisor forks
        lock = ServiceLock(self.config.name)
        try:
            removed = naming.remove_leftovers(self.config.name)
            if removed:
                log.warning("removed %d leftovers of an earlier run: %s", len(removed), " ".join(removed))
            self._start_all()  # a StartError: the command says it, once all is stopped and removed
            self._announce()
            return self._watch()
        finally:
            self._stop_all()
            naming.remove_leftovers(self.config.name)
            remove_stale_ipc_files(self.config)
            lock.release()

    def _start_all(self) -> None:
        self._start(self.cameras)
        self._start([self.coordinator])  # reads the cameras' rings
        for viewer in self.viewers:  # a reader like any client: after the service it reads
            self._start([viewer])

    def _start(self, children: list[Child]) -> None:
        """Start ``children`` together; each is in the table from its start on (see _restart) and
        "running" from its handshake on."""
        for child in children:
            child.start()
        self._write_state()
        for child in children:
            child.wait_ready()
            child.state = "running"
        self._write_state()

    def _announce(self) -> None:
        c = self.config
        lines = [f"fxis: service {c.name!r} is serving {len(c.cameras)} camera(s)"]
        for cam in c.cameras:  # the options in force: the service's --history where the camera has none
            options = {**cam.options, "history": history_of(cam, c)}
            opts = ", ".join(f"{k}={v}" for k, v in options.items() if v is not None)
            lines.append(f"  {cam.name:<10} {cam.kind:<10} {opts}")
        lines.append(f"  requests on {c.endpoint}, publishing on {c.pub}, request events on {c.events}")
        lines += ring_lines(c)
        lines += viewer_lines(c, self.viewer_access)
        if c.ros2 is not None:
            tuples = f", tuples at {c.ros2.tuples_hz:g} Hz" if c.ros2.tuples_hz else ""
            lines.append(f"  ROS 2 topics under {c.ros2.namespace or '/'} on DDS domain {c.ros2.domain}{tuples}")
        lines += change_lines(c)
        if c.curve_secret:
            lines.append(f"  CurveZMQ: only the clients whose keys are in {c.curve_clients}")
        if c.exposed_unencrypted:
            lines.append(
                f"  WARNING: {', '.join(c.exposed_unencrypted)} reachable from other hosts "
                "WITHOUT authentication or encryption (--insecure-bind)"
            )
        lines.append("  Ctrl-C stops the service.")
        print("\n".join(lines), file=self.out, flush=True)

    def _watch(self) -> int:
        assert self.stop is not None
        while not self.stop.wait(0.1):
            for child in self.children:
                code = child.exited()
                if code is not None and child.restart_at is None:
                    if not self._schedule_restart(child, code):
                        if child is self.coordinator:
                            print("fxis: the coordinator keeps failing; stopping", file=sys.stderr)
                            return 1
                if child.restart_at is not None and time.monotonic() >= child.restart_at:
                    self._restart(child)
        return 0

    def _schedule_restart(self, child: Child, code: int) -> bool:
        now, limit, window = time.monotonic(), self.config.restart_limit, self.config.restart_window_s
        if now - child.started_at > STABLE_AFTER_S:
            child.backoff = BACKOFF_FIRST_S
        child.last_exit = code
        child.crashes = recent_crashes([*child.crashes, now], now, window)
        if gives_up(child.crashes, now, limit, window):
            log.error(
                "%s exited with code %s; restart limit of %d in %g s reached, leaving it down",
                child.label,
                code,
                limit,
                window,
            )
            child.restart_at = float("inf")
            child.state = "given up"
            self._event(child, f"exited with code {code}; restart limit reached, left down")
            return False
        log.warning("%s exited with code %s; restarting in %.1f s", child.label, code, child.backoff)
        child.restart_at = time.monotonic() + child.backoff
        child.backoff = min(child.backoff * 2, BACKOFF_MAX_S)
        child.state = "restarting"
        self._event(child, f"exited with code {code}; restarting")
        return True

    def _restart(self, child: Child) -> None:
        child.restarts += 1
        child.start()
        # The table names the new pid and count before the child is ready: a coordinator answers
        # status as soon as it is, and must not serve the table of its predecessor.
        self._write_state()
        try:
            child.wait_ready()
            log.info("%s restarted (restart %d)", child.label, child.restarts)
            child.state = "running"
            self._event(child, f"restarted (restart {child.restarts})")
        except StartError as exc:
            log.error("restart failed: %s", exc)
            child.kill()
            self._event(child, f"restart failed: {exc}")

    def _event(self, child: Child, what: str) -> None:
        self.events = (self.events + [{"process": child.key, "t": time.monotonic_ns(), "what": what}])[-20:]
        self._write_state()

    def _write_state(self) -> None:
        """The process table, for the coordinator's status (written whole, then renamed)."""
        state: SupervisorState = {
            "pid": os.getpid(),
            "processes": {
                c.key: {
                    "pid": c.proc.pid if c.proc else None,
                    "state": c.state,
                    "restarts": c.restarts,
                    "last_exit": c.last_exit,
                }
                for c in self.children
            },
            "events": self.events,
        }
        path = naming.supervisor_state_path(self.config.name)
        try:
            with open(path + ".tmp", "w") as f:
                json.dump(state, f)
            os.chmod(path + ".tmp", 0o600)
            os.replace(path + ".tmp", path)
        except OSError as exc:
            log.warning("could not write %s: %s", path, exc)

    def _stop_all(self) -> None:
        for child in self.children:
            child.terminate()
        deadline = time.monotonic() + STOP_GRACE_S
        for child in self.children:
            if child.proc is None:
                continue
            try:
                child.proc.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                log.warning("%s did not stop within %.0f s; killing it", child.label, STOP_GRACE_S)
                child.kill()
                child.proc.wait()
