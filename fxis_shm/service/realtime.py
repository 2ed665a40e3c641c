"""The OS calls of ``fxis run --realtime``: SCHED_FIFO for a process's threads, memory locked,
whether either can be had, and each thread's policy read back. The decisions (which thread at
which priority, when memory may be locked) are fxis_shm.service.rtpolicy's.

Every thread is set with SCHED_RESET_ON_FORK: what it forks (a hook's process, a pool's) and the
threads it starts begin at normal priority, so only the threads named real-time ever are.
"""

from __future__ import annotations

import ctypes
import errno
import os
import resource
import threading
import time
from collections.abc import Callable

from fxis_shm.formats.threadsched import tasks, threads_of
from fxis_shm.service import rtpolicy
from fxis_shm.wire.statusdoc import SupervisorState

_MCL_CURRENT, _MCL_FUTURE = 1, 2
_CAP_SYS_NICE, _CAP_IPC_LOCK = 23, 14


def _set_fifo(tid: int, priority: int) -> None:
    os.sched_setscheduler(tid, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))


def refusal(priority: int) -> str | None:
    """None if this process's threads may run SCHED_FIFO at ``priority``, else why not (one line),
    found by trying it on a thread of its own that ends at once."""
    errors: list[OSError] = []

    def attempt() -> None:
        try:
            _set_fifo(0, priority)
        except OSError as exc:
            errors.append(exc)

    thread = threading.Thread(target=attempt, name="realtime-probe")
    thread.start()
    thread.join()
    if not errors:
        return None
    exc = errors[0]
    rtprio = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
    if exc.errno != errno.EPERM:
        return f"SCHED_FIFO {priority} refused: {exc.strerror}"
    if _capable(_CAP_SYS_NICE) or rtprio == resource.RLIM_INFINITY or rtprio >= priority:
        why = "no real-time runtime in this cgroup (RT group scheduling: its cpu.rt_runtime_us is 0)"
    else:
        why = f"no CAP_SYS_NICE and RLIMIT_RTPRIO {rtprio} (below {priority})"
    return f"SCHED_FIFO {priority} refused (EPERM: {why})"


def memory_lockable() -> bool:
    limit = resource.getrlimit(resource.RLIMIT_MEMLOCK)[0]
    return rtpolicy.memory_lock_allowed(limit, resource.RLIM_INFINITY, _capable(_CAP_IPC_LOCK))


def lock_refusal() -> str:
    limit = resource.getrlimit(resource.RLIMIT_MEMLOCK)[0]
    return f"memory not locked (RLIMIT_MEMLOCK {limit} bytes and no CAP_IPC_LOCK)"


def lock_memory() -> str | None:
    """mlockall(MCL_CURRENT | MCL_FUTURE) where it is safe (rtpolicy.memory_lock_allowed); None
    if done or not safe (``fxis run`` said so at start, in its one line), else why it failed."""
    if not memory_lockable():
        return None
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE) != 0:
        return f"memory not locked: {os.strerror(ctypes.get_errno())}"
    return None


def raise_this_thread(role: str, priority: int | None) -> None:
    """The calling thread at the priority of its ``role`` (``priority`` None: --realtime is off);
    a refusal is left to raise_threads's sweep, which reports it."""
    wanted = None if priority is None else rtpolicy.priority_of(role, priority)
    if wanted is not None:
        try:
            _set_fifo(0, wanted)
        except OSError:
            pass


def raise_threads(role_of: Callable[[str | None, str], str], priority: int) -> list[str]:
    """Set every thread of this process to the priority its role gives (rtpolicy.priority_of);
    ``role_of(python_name or None, comm)``. Returns what failed, one line each."""
    # the main thread's tid is the pid: after a fork (service/forkstart.py) Python still gives it the parent's
    names = {t.native_id: t.name for t in threading.enumerate() if t.native_id is not None}
    names[os.getpid()] = threading.main_thread().name
    failed = []
    for tid in _settled_tasks(names):
        wanted = rtpolicy.priority_of(role_of(names.get(tid), _comm(tid)), priority)
        if wanted is None:
            continue
        try:
            _set_fifo(tid, wanted)
        except OSError as exc:
            failed.append(f"thread {tid} ({names.get(tid) or _comm(tid)}): {exc.strerror}")
    return failed


def _settled_tasks(names: dict[int, str], wait_s: float = 1.0) -> list[int]:
    """This process's threads but those still being born. A thread libzmq starts sets its own
    scheduling first thing (pthread_getschedparam, then pthread_setschedparam) and only then its
    name: set to FIFO between those two calls, it reads the old priority with the new policy, the
    kernel refuses the pair (EINVAL) and libzmq aborts the process. Such a newborn still carries
    the name of the thread that made it; it is waited for (``wait_s`` at most) and else left as it
    is, never changed mid-birth."""
    deadline = time.monotonic() + wait_s
    while True:
        python_comms = {_comm(tid) for tid in names}
        tids = tasks("self")
        newborn = [tid for tid in tids if tid not in names and _comm(tid) in python_comms]
        if not newborn or time.monotonic() > deadline:
            return [tid for tid in tids if tid not in newborn]
        time.sleep(0.005)


def with_scheduling(state: SupervisorState | None) -> SupervisorState | None:
    """A supervisor's state (its process table) with each running process's scheduling
    (``sched``: rtpolicy.summary of its threads, None once it is gone)."""
    if state is None:
        return None
    for process in state.get("processes", {}).values():
        pid = process.get("pid")
        threads = threads_of(pid) if isinstance(pid, int) else {}
        process["sched"] = rtpolicy.summary(threads.values()) if threads else None
    return state


def _comm(tid: int) -> str:
    try:
        with open(f"/proc/self/task/{tid}/comm") as f:
            return f.read().strip()
    except OSError:
        return ""


def _capable(cap: int) -> bool:
    """Whether this process has capability ``cap`` in its effective set (/proc/self/status)."""
    try:
        with open("/proc/self/status") as f:
            line = next(line for line in f if line.startswith("CapEff:"))
    except (OSError, StopIteration):
        return False
    return bool(int(line.split()[1], 16) >> cap & 1)
