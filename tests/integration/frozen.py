"""Rings held still while a test reads them (and how far back they reach): the cameras' workers
stopped (SIGSTOP), so that no frame is stored, and none overwritten, between two reads.

On a loaded machine (the suite's parallel pass: 5 workers on 2 cores) any process may be held
up for a second or more between two reads; a test that reads the newest frame and then asks for
frames near the oldest end of a small ring, or compares an answer with the ring's frames read
after it, would find the ring moved on. Stopped, it stays as it was read.

A stopped worker stores no frame and so reports nothing: the service counts its camera down 2 s
after its last frame (fxis_shm.shm.cameras.STALE_HEARTBEAT_NS). A freeze holds a few reads."""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator

from ..conftest import wait_until


@contextlib.contextmanager
def frozen(client, *cameras: str) -> Iterator[None]:
    """The workers of ``cameras`` (of ``client``'s service) stopped for the block, and continued
    after it whatever happened. The block starts once every thread of each worker has stopped:
    a worker running on the other core takes the signal a moment after the kill, and may store
    one more frame meanwhile."""
    processes = client.status()["supervisor"]["processes"]
    pids = [processes[f"camera:{name}"]["pid"] for name in cameras]
    stopped = []
    try:
        for pid in pids:
            os.kill(pid, signal.SIGSTOP)
            stopped.append(pid)
        wait_until(lambda: all(_stopped(pid) for pid in pids), timeout=5, what=f"the workers of {cameras} to stop")
        yield
    finally:
        for pid in stopped:
            os.kill(pid, signal.SIGCONT)


def _stopped(pid: int) -> bool:
    """True once every thread of ``pid`` is stopped (state T in /proc/PID/task/TID/stat), or
    ending (Z, X: it runs no more)."""
    tasks = f"/proc/{pid}/task"
    for tid in os.listdir(tasks):
        try:
            with open(f"{tasks}/{tid}/stat", "rb") as f:
                state = f.read().rsplit(b")", 1)[1].split()[0]
        except OSError:  # a thread that ended meanwhile
            continue
        if state not in (b"T", b"t", b"Z", b"X"):
            return False
    return True


def held_by_every_ring_ns(client) -> int:
    """How far back from the newest moment every camera has stored a frame every ring reaches."""
    times = client.frame_times()
    i_t = times["columns"].index("t_capture")
    rows = [camera["frames"] for camera in times["cameras"].values()]
    return min(r[-1][i_t] for r in rows) - max(r[0][i_t] for r in rows) if all(rows) else 0


def newest_of_all(client, **options) -> int:
    """The capture time of the newest frame every camera has stored (each one's newest, the
    oldest of them): frames of every camera up to it are stored, none still to come.
    ``options``: latest()'s."""
    return min(frame.t_capture for frame in client.latest(**options).values())
