"""Emulated hosts for tests and benches: other computers of a robot cell, on this one.

An ``EmulatedHost`` is
- a network namespace joined to this (the root) namespace by a veth pair, with a /30 of
  TEST-NET-2 (198.51.100.0/24): the host at .4k+2, our side of the link at .4k+1. No other
  address is ever used, and traffic stays between namespaces made here;
- its own CLOCK_MONOTONIC: what runs in it runs in a time namespace whose monotonic clock
  is ahead of ours by a whole number of seconds (util-linux's ``unshare --monotonic``
  takes seconds), so the true offset is known exactly;
- its own /dev/shm: a mount namespace with a fresh tmpfs there (so the local fast path
  cannot be taken by accident: different clock, different rings);
- a rate-limited link: a token bucket (``tc ... tbf``) on both ends, e.g. "1gbit" or
  "100mbit". No added delay: this kernel has no netem.

A ``Lab`` owns its hosts and the CurveZMQ keys their services use (services bind a
non-loopback address, so they need keys), and tears everything down on ``close`` (the
services, anything else left in the namespaces, the namespaces, the links with their
qdiscs), also when the code using it raised. Names start with "fxt", then the owning
process's id: a new Lab first removes what earlier runs, whose process is gone, left behind.

Needs root (CAP_NET_ADMIN and CAP_SYS_ADMIN), iproute2 (ip, tc), util-linux (unshare) and
a kernel with time namespaces (Linux >= 5.6); ``check_support`` says what is missing.

    from tests.hosts import Lab
    with Lab() as lab:
        host = lab.host(clock_offset_s=1000, rate="1gbit")
        svc = host.service("--camera", "a=synthetic")
        with Client(svc.endpoint, keys=lab.client_keys) as client:
            frame = client.image("a")     # frame.service_t_capture - host.clock_offset_ns ~ our clock

Used by tests/integration/test_hosts.py (the ``emulated_hosts`` fixture in tests/conftest.py)
and bench/network/remote.py (with the repository's root on sys.path).
"""

from __future__ import annotations

import contextlib
import fcntl
import ipaddress
import itertools
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence

from fxis_shm.service.launch import ServiceProcess
from fxis_shm.wire.security import ClientKeys, create_keys

PREFIX = "fxt"
SUBNET = ipaddress.ip_network("198.51.100.0/24")  # TEST-NET-2 (RFC 5737): never routed anywhere
SERVICE_PORT = 5555  # request endpoint; publish and events on the next two ports
ALLOCATION_LOCK = "/run/lock/fxt-hosts.lock"  # concurrent runs pick different /30s under it
LINK_BURST = "64kb"  # token-bucket depth: 0.5 ms at 1 Gbit/s, about what a switch port buffers
LINK_QUEUE_LATENCY = "100ms"  # longest a packet may wait in the shaper before it is dropped
COMMAND_TIMEOUT_S = 30.0

_NAME = re.compile(rf"^{PREFIX}(\d+)([hr])(\d+)$")  # fxt<pid>h<k>: namespace, fxt<pid>r<k>: our end
_numbers = itertools.count()  # per process: no two hosts of one run share a name


class HostsUnavailable(RuntimeError):
    """Emulated hosts cannot be made here; the message says what is missing."""


def check_support() -> None:
    """Raise ``HostsUnavailable`` saying why emulated hosts cannot be made here."""
    if os.geteuid() != 0:
        raise HostsUnavailable(
            "emulated hosts need root (network, mount and time namespaces, veth links, "
            "tc): run these tests as root (CI does)"
        )
    missing = [tool for tool in ("ip", "tc", "unshare", "mount") if shutil.which(tool) is None]
    if missing:
        raise HostsUnavailable(
            f"emulated hosts need {', '.join(missing)} (iproute2, util-linux): run scripts/install-system-packages.sh"
        )
    if not os.path.exists("/proc/self/ns/time"):
        raise HostsUnavailable(
            "emulated hosts need time namespaces (Linux >= 5.6 with CONFIG_TIME_NS); "
            f"this kernel is {os.uname().release}"
        )


def _run(*argv: str, check: bool = True) -> subprocess.CompletedProcess:
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise HostsUnavailable(f"{' '.join(argv)} did not finish within {COMMAND_TIMEOUT_S:.0f} s") from None
    if check and done.returncode != 0:
        raise HostsUnavailable(f"{' '.join(argv)} failed: {done.stderr.strip() or done.returncode}")
    return done


# ---- what exists: namespaces and links by name ----------------------------------------------


def namespaces() -> list[str]:
    return [line.split()[0] for line in _run("ip", "netns", "list").stdout.splitlines() if line.strip()]


def links() -> list[str]:
    """Names of the links of the root namespace."""
    out = _run("ip", "-o", "link", "show").stdout
    return [line.split(":")[1].strip().split("@")[0] for line in out.splitlines() if ":" in line]


def ours(names: Sequence[str]) -> list[str]:
    """The names an emulated host could have made."""
    return [n for n in names if _NAME.match(n)]


def _owner_alive(name: str) -> bool:
    return os.path.exists(f"/proc/{_NAME.match(name).group(1)}")


def _end_processes(netns: str, grace_s: float = 5.0) -> None:
    """End every process in ``netns`` (ours: services and commands run in a host): SIGTERM,
    then SIGKILL whatever is still there after ``grace_s``."""

    def pids():
        done = _run("ip", "netns", "pids", netns, check=False)
        return [int(p) for p in done.stdout.split()] if done.returncode == 0 else []

    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in pids():
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, sig)
        deadline = time.monotonic() + grace_s
        while pids() and time.monotonic() < deadline:
            time.sleep(0.05)
        if not pids():
            return


def _remove(netns: str | None, link: str | None) -> None:
    if netns and netns in namespaces():
        _end_processes(netns)
        _run("ip", "netns", "delete", netns, check=False)
    if link and link in links():  # normally gone with its peer in the namespace
        _run("ip", "link", "delete", link, check=False)


def remove_leftovers() -> list[str]:
    """Remove the namespaces and links of emulated hosts whose owning process is gone
    (a run that crashed or was killed); returns their names."""
    stale_ns = [n for n in ours(namespaces()) if not _owner_alive(n)]
    for n in stale_ns:
        _remove(n, None)
    stale_links = [n for n in ours(links()) if not _owner_alive(n)]
    for n in stale_links:
        _remove(None, n)
    return stale_ns + stale_links


# ---- addresses ------------------------------------------------------------------------------


def _free_subnet() -> ipaddress.IPv4Network:
    """A /30 of TEST-NET-2 that no address of the root namespace is in (call under the lock)."""
    used = set()
    for line in _run("ip", "-o", "-4", "addr", "show").stdout.splitlines():
        address = ipaddress.ip_interface(line.split()[3]).ip
        if address in SUBNET:
            used.add(address)
    for subnet in SUBNET.subnets(new_prefix=30):
        if not any(a in subnet for a in used):
            return subnet
    raise HostsUnavailable(f"every /30 of {SUBNET} is in use: too many emulated hosts at once")


@contextlib.contextmanager
def _allocation_lock():
    os.makedirs(os.path.dirname(ALLOCATION_LOCK), exist_ok=True)
    with open(ALLOCATION_LOCK, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


# ---- a host ---------------------------------------------------------------------------------


class EmulatedHost:
    """One emulated computer; made by ``Lab.host``."""

    def __init__(self, lab: Lab, clock_offset_s: int, rate: str | None):
        if int(clock_offset_s) != clock_offset_s or clock_offset_s < 0:
            raise ValueError(
                f"clock_offset_s must be a whole number of seconds >= 0 "
                f"(unshare --monotonic takes seconds), got {clock_offset_s!r}"
            )
        self.lab = lab
        k = next(_numbers)
        self.netns = f"{PREFIX}{os.getpid()}h{k}"
        self.link = f"{PREFIX}{os.getpid()}r{k}"  # our end; the host's end is named ...n<k>
        self.inner_link = f"{PREFIX}{os.getpid()}n{k}"
        self.clock_offset_s = int(clock_offset_s)
        self.rate = rate
        self.address = self.gateway = None
        self.services: list[ServiceProcess] = []
        self._ports = itertools.count(SERVICE_PORT, 3)

    @property
    def clock_offset_ns(self) -> int:
        """This host's CLOCK_MONOTONIC minus ours, exactly."""
        return self.clock_offset_s * 1_000_000_000

    def monotonic_ns(self) -> int:
        """What ``time.monotonic_ns()`` says on this host now."""
        return time.monotonic_ns() + self.clock_offset_ns

    def _create(self) -> None:
        with _allocation_lock():
            subnet = _free_subnet()
            self.gateway, self.address = (str(a) for a in itertools.islice(subnet.hosts(), 2))
            _run("ip", "netns", "add", self.netns)
            _run("ip", "link", "add", self.link, "type", "veth", "peer", "name", self.inner_link, "netns", self.netns)
            _run("ip", "addr", "add", f"{self.gateway}/30", "dev", self.link)
        _run("ip", "link", "set", self.link, "up")
        inside = ("ip", "netns", "exec", self.netns)
        _run(*inside, "ip", "addr", "add", f"{self.address}/30", "dev", self.inner_link)
        _run(*inside, "ip", "link", "set", self.inner_link, "up")
        _run(*inside, "ip", "link", "set", "lo", "up")
        if self.rate:
            self.set_rate(self.rate)

    def set_rate(self, rate: str | None) -> None:
        """Limit the link to ``rate`` (tc's syntax: "1gbit", "100mbit") each way; None: unlimited."""
        for prefix, dev in (((), self.link), (("ip", "netns", "exec", self.netns), self.inner_link)):
            if rate:
                _run(
                    *prefix,
                    "tc",
                    "qdisc",
                    "replace",
                    "dev",
                    dev,
                    "root",
                    "tbf",
                    "rate",
                    rate,
                    "burst",
                    LINK_BURST,
                    "latency",
                    LINK_QUEUE_LATENCY,
                )
            else:
                _run(*prefix, "tc", "qdisc", "delete", "dev", dev, "root", check=False)
        self.rate = rate

    def link_bytes(self) -> dict:
        """Bytes the link carried so far each way (the shapers' counters, headers included):
        {"to_host": ..., "from_host": ...}; 0 without a rate limit."""

        def sent(*prefix, dev):
            out = _run(*prefix, "tc", "-s", "qdisc", "show", "dev", dev).stdout
            found = re.search(r"Sent (\d+) bytes", out)
            return int(found.group(1)) if found and self.rate else 0

        return {
            "to_host": sent(dev=self.link),
            "from_host": sent("ip", "netns", "exec", self.netns, dev=self.inner_link),
        }

    def wrapper(self) -> list[str]:
        """A command prefix that runs a program on this host: its network, clock and /dev/shm.
        Every step execs the next (no fork), so a signal to the child reaches the program."""
        return [
            "ip",
            "netns",
            "exec",
            self.netns,
            "unshare",
            "--mount",
            "--propagation",
            "private",
            "--time",
            f"--monotonic={self.clock_offset_s}",
            "--",
            "sh",
            "-c",
            'mount -t tmpfs -o mode=1777 fxt-shm /dev/shm && exec "$@"',
            "fxt-host",
        ]

    def run(self, argv: Sequence[str], timeout: float = COMMAND_TIMEOUT_S) -> subprocess.CompletedProcess:
        """Run a command on this host and wait for it (output captured as text)."""
        return subprocess.run([*self.wrapper(), *argv], capture_output=True, text=True, timeout=timeout)

    def endpoints(self, port: int) -> tuple[str, str, str]:
        return tuple(f"tcp://{self.address}:{p}" for p in (port, port + 1, port + 2))

    def service(self, *args: str, name: str | None = None, ready_timeout: float = 60.0) -> ServiceProcess:
        """Start ``fxis run ARGS`` on this host, bound to its address with the lab's CurveZMQ
        keys; returns it once it answers. The lab stops it on close; ``.stop()`` and
        ``.start()`` stop it and bring it back at the same endpoints."""
        endpoint, pub, events = self.endpoints(next(self._ports))
        log = open(os.path.join(self.lab.log_dir, f"{self.netns}-{len(self.services)}.log"), "wb")
        self.lab.closing.callback(log.close)
        svc = ServiceProcess(
            [*args, "--curve-secret", self.lab.server_secret, "--curve-clients", self.lab.allowed],
            name=name,
            endpoint=endpoint,
            pub=pub,
            events=events,
            ready_timeout=ready_timeout,
            stderr=log,
            client_keys=self.lab.client_keys,
            wrapper=self.wrapper(),
        )
        self.services.append(svc)
        return svc.start()

    def close(self) -> None:
        for svc in self.services:
            svc.stop()
        _remove(self.netns, self.link)

    def __repr__(self) -> str:
        return (
            f"EmulatedHost({self.netns}, {self.address}, clock +{self.clock_offset_s} s, "
            f"link {self.rate or 'unlimited'})"
        )


class LoopbackNamespace:
    """This host as seen by programs that multicast in their default configuration (Fast DDS's
    discovery does): a network namespace holding only ``lo``, with multicast on and routed, so
    their traffic can reach nothing but each other. Same clock and /dev/shm as ours, so programs
    in it are on one host (Fast DDS's shared memory transport included). A context manager;
    ``wrapper`` runs a program in it. Named like an emulated host, so leftovers are cleaned alike."""

    def __init__(self) -> None:
        check_support()
        remove_leftovers()
        self.netns = f"{PREFIX}{os.getpid()}h{next(_numbers)}"
        try:
            _run("ip", "netns", "add", self.netns)
            inside = ("ip", "netns", "exec", self.netns)
            _run(*inside, "ip", "link", "set", "lo", "up", "multicast", "on")
            _run(*inside, "ip", "route", "add", "224.0.0.0/4", "dev", "lo")
        except BaseException:
            self.close()
            raise

    def wrapper(self) -> list[str]:
        return ["ip", "netns", "exec", self.netns]

    def close(self) -> None:
        _remove(self.netns, None)

    def __enter__(self) -> LoopbackNamespace:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Lab:
    """Emulated hosts, their CurveZMQ keys, and their teardown. A context manager."""

    def __init__(self, log_dir: str | None = None):
        check_support()
        self.closing = contextlib.ExitStack()
        self._keys_dir = self.closing.enter_context(tempfile.TemporaryDirectory(prefix="fxt-keys-"))
        self.log_dir = log_dir or self._keys_dir
        self.hosts: list[EmulatedHost] = []
        try:
            remove_leftovers()
            # one server key pair for every host of the lab, so one ClientKeys opens them all
            keys = os.path.join(self._keys_dir, "keys")
            self.allowed = os.path.join(self._keys_dir, "allowed")
            _, self.server_secret = create_keys(keys, "server")
            client_public, client_secret = create_keys(keys, "client")
            os.makedirs(self.allowed, mode=0o700)
            shutil.copy(client_public, self.allowed)
            self.client_keys = ClientKeys.from_files(os.path.join(keys, "server.key"), client_secret)
            # the same keys as files, for a command line (fxis ... --server-key, --client-key)
            self.key_files = (os.path.join(keys, "server.key"), client_secret)
        except BaseException:
            self.closing.close()
            raise

    def host(self, clock_offset_s: int = 1000, rate: str | None = "1gbit") -> EmulatedHost:
        """A new emulated host whose clock is ``clock_offset_s`` ahead of ours, on a link of ``rate``."""
        host = EmulatedHost(self, clock_offset_s, rate)
        self.hosts.append(host)  # before it exists: a half-made host is removed too
        host._create()
        return host

    def leftovers(self) -> list[str]:
        """Namespaces and links of this lab that still exist (none after ``close``)."""
        names = {h.netns for h in self.hosts} | {h.link for h in self.hosts}
        return sorted(names & (set(namespaces()) | set(links())))

    def close(self) -> None:
        try:
            for host in reversed(self.hosts):
                host.close()
        finally:
            self.closing.close()

    def __enter__(self) -> Lab:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@contextlib.contextmanager
def loopback_address(address: str):
    """``address`` (127.x.y.z) on lo while the block runs: added if missing (needs root), removed
    afterwards; HostsUnavailable if it cannot be added. For emulated cameras and devices of their
    own address (tests/backends, bench/cameras/gige.py)."""
    shown = _run("ip", "-o", "-4", "addr", "show", "dev", "lo").stdout
    added = f" {address}/" not in shown
    if added:
        done = _run("ip", "addr", "add", f"{address}/8", "dev", "lo", check=False)
        if done.returncode != 0:
            raise HostsUnavailable(
                f"{address} is not on lo and `ip addr add {address}/8 dev lo` failed (needs root): "
                f"{done.stderr.strip()}"
            )
    try:
        yield address
    finally:
        if added:
            _run("ip", "addr", "del", f"{address}/8", "dev", "lo", check=False)


def main(argv: list[str] | None = None) -> int:
    """``python -m tests.hosts clean``: remove what crashed runs left behind; ``list``: show
    the namespaces and links of emulated hosts that exist now."""
    command = (argv if argv is not None else sys.argv[1:]) or ["list"]
    if command[0] == "clean":
        removed = remove_leftovers()
        print("removed: " + (", ".join(removed) or "nothing"))
    else:
        names = ours(namespaces()) + ours(links())
        for name in names:
            print(name, "(owner running)" if _owner_alive(name) else "(left over)")
        if not names:
            print("no namespaces or links of emulated hosts")
    return 0


if __name__ == "__main__":
    sys.exit(main())
