"""The scheduling of a process's threads, read from /proc, and ``normal_scheduling_kept``: the
guard a video encoder opens under.

SVT-AV1 (FFmpeg's ``libsvtav1``), run as root, puts the thread that opens an encoder at
SCHED_FIFO 99: ``svt_av1_enc_init_handle`` calls ``pthread_setschedparam(pthread_self(),
SCHED_FIFO, 99)`` whenever ``geteuid() == 0``, and no parameter turns it off. The threads it
then starts for the encoder (``svt_create_thread``: the default attributes, which inherit the
creator's policy) run at FIFO 99 too. A recorder, an exporter or a snapshot's writer would then
encode above the cameras' trigger timers (FIFO 40 with ``--realtime``) and the kernel's own
real-time threads (FIFO 50), which is what ``--realtime`` promises never happens (docs/sync.md).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

_REAL_TIME = (os.SCHED_FIFO, os.SCHED_RR)


def threads_of(pid: int | str) -> dict[int, tuple[int, int]]:
    """Each thread of ``pid`` -> its (policy, rt_priority) (proc(5): fields 41 and 40 of its
    stat); {} if it is gone."""
    found = {}
    for tid in tasks(pid):
        try:
            with open(f"/proc/{pid}/task/{tid}/stat", "rb") as f:
                raw = f.read()
        except OSError:
            continue
        fields = raw[raw.rfind(b")") + 2 :].split()  # fields[0] is field 3 of proc(5)
        found[tid] = (int(fields[38]), int(fields[37]))
    return found


def tasks(pid: int | str) -> list[int]:
    """The thread ids of ``pid`` ("self": this process); [] if it is gone."""
    try:
        return [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    except OSError:
        return []


@contextmanager
def normal_scheduling_kept() -> Iterator[None]:
    """Run the block (an encoder's open) and then undo what it did to scheduling: the calling
    thread back at its own policy and priority, and each thread born meanwhile at a real-time
    policy at SCHED_OTHER (an encoder's threads never do real-time work)."""
    policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
    before = set(tasks("self"))
    try:
        yield
    finally:
        os.sched_setscheduler(0, policy, param)
        for tid, (born_policy, _) in threads_of("self").items():
            if tid not in before and born_policy in _REAL_TIME:
                try:
                    os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
                except OSError:  # (ended meanwhile)
                    pass
