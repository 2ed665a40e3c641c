"""DDS settings for tests: every packet on 127.0.0.1 (fxis_shm.ros2.loopback), and a domain id of
its own for each test.

Loopback only because this host's ``lo`` has no MULTICAST flag and its other interface must
never carry test traffic. Each test takes a domain id nobody else on the host holds (a lock
file per id), so tests running at once, here or in another pytest, never see each other's
participants; an id is not reused within a session either, since a killed peer's participant
is remembered until its lease runs out.
"""

from __future__ import annotations

import fcntl
import os
import tempfile

from fxis_shm.ros2.loopback import loopback_config as loopback_config  # the bridge's, for the peer too

FIRST_DOMAIN, LAST_DOMAIN = 1, 232  # 0 is ROS's default; 232 the highest DDS's port mapping allows
_LOCKS = os.path.join(tempfile.gettempdir(), "fxis-dds-domains")
_held: dict[int, int] = {}  # domain id -> the descriptor holding its lock, open for the session


def domain_id() -> int:
    """A DDS domain id no other test (of any process on this host) holds, kept for the session."""
    os.makedirs(_LOCKS, exist_ok=True)
    count = LAST_DOMAIN - FIRST_DOMAIN + 1
    start = os.getpid() % count  # concurrent sessions start apart and rarely contend
    for step in range(count):
        candidate = FIRST_DOMAIN + (start + step) % count
        if candidate in _held:
            continue
        fd = os.open(os.path.join(_LOCKS, f"{candidate}.lock"), os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            continue
        _held[candidate] = fd
        return candidate
    raise RuntimeError(f"every DDS domain id {FIRST_DOMAIN}..{LAST_DOMAIN} is taken on this host")
