"""What ``fxis run --realtime`` asks for, decided without touching the OS: the option parsed,
the priority of each thread by its role, whether memory may be locked, and a process's
threads' scheduling summed up for status. The OS calls are fxis_shm.service.realtime's.

Priorities (SCHED_FIFO, 1..99): the kernel runs its threaded interrupt handlers and watchdogd
at 50 and its migration threads at 99, so the service stays below 50: the trigger timers at
PRIORITY (40 by default), the other threads of the request and capture path one below. A
timer then preempts its own process's capture loop and the coordinator, and nothing of the
service preempts the kernel's interrupt threads.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from fxis_shm.errors import ConfigError
from fxis_shm.wire.statusdoc import Scheduling

DEFAULT_PRIORITY = 40
KERNEL_PRIORITY = 50  # the kernel's threaded interrupt handlers (irq/N-...) and watchdogd
LOWEST_PRIORITY = 2  # the other threads run one below it, and 1 is SCHED_FIFO's lowest
REQUIRE = "require"
# /proc/PID/task/TID/stat's policy field (sched(7)); 4 is unused
POLICIES = {0: "other", 1: "fifo", 2: "rr", 3: "batch", 5: "idle", 6: "deadline"}
REAL_TIME = ("fifo", "rr", "deadline")

# the roles of threads (thread_priority)
TIMER = "timer"  # a camera worker's trigger timer: fires at a moment
PATH = "path"  # the capture loop, the command and trigger listeners, the coordinator's loop, their sockets' I/O
NORMAL = "normal"  # everything else: hooks, thread pools, housekeeping

# a camera worker's Python threads by name (workers/camera.py, triggers.py, commands.py)
_CAMERA_THREADS = {"trigger-timer": TIMER, "MainThread": PATH, "trigger": PATH, "commands": PATH}
_ZMQ_IO = "ZMQbg/IO/"  # libzmq names its I/O threads so (/proc/.../comm); its reaper "ZMQbg/Reaper"


@dataclass(frozen=True)
class Realtime:
    priority: int = DEFAULT_PRIORITY  # of the trigger timers; the rest of the path one below
    require: bool = False  # stop the start when SCHED_FIFO cannot be had, instead of going on without


def parse_realtime(value: object) -> Realtime | None:
    """``realtime`` as a flag or config value: true/"on"/"" (the default priority), a priority,
    "require" or "PRIORITY,require"; false/"off"/None: off. ConfigError saying what is allowed."""
    if value is None or value is False:
        return None
    if value is True:
        return Realtime()
    if isinstance(value, int):
        return Realtime(_priority(value))
    words = [w.strip().lower() for w in str(value).split(",")]
    if words in (["off"], ["false"], ["no"]):
        return None
    require = REQUIRE in words
    rest = [w for w in words if w not in (REQUIRE, "", "on", "true", "yes")]
    if len(rest) > 1 or (rest and not rest[0].isdigit()):
        raise ConfigError(f"realtime must be on, off, a priority, require or PRIORITY,require; got {value!r}")
    return Realtime(_priority(int(rest[0])) if rest else DEFAULT_PRIORITY, require)


def _priority(value: int) -> int:
    if isinstance(value, bool) or not LOWEST_PRIORITY <= value < KERNEL_PRIORITY:
        raise ConfigError(
            f"realtime priority must be {LOWEST_PRIORITY}..{KERNEL_PRIORITY - 1}, got {value!r}: the kernel's "
            f"interrupt threads run at {KERNEL_PRIORITY} (its migration threads at 99), and the service's threads "
            "must not hold them off"
        )
    return value


def priority_of(role: str, priority: int) -> int | None:
    """The SCHED_FIFO priority of a thread of ``role`` (None: it stays at normal priority)."""
    return {TIMER: priority, PATH: priority - 1}.get(role)


def camera_thread_role(python_name: str | None, comm: str, inline_hook: bool) -> str:
    """A camera worker's thread's role: by its Python name, or (a thread of a library: a ZeroMQ
    I/O thread, a camera SDK's stream thread) on the path. A capture loop that runs a processing
    hook inline stays at normal priority: a hook's time is not bounded."""
    if python_name is None:
        return NORMAL if comm.startswith("ZMQbg/") and not comm.startswith(_ZMQ_IO) else PATH
    role = _CAMERA_THREADS.get(python_name, NORMAL)
    return NORMAL if python_name == "MainThread" and inline_hook else role


def coordinator_thread_role(python_name: str | None, comm: str) -> str:
    """The coordinator's loop (its main thread) and its sockets' I/O threads are on the path;
    the CurveZMQ authenticator and the rest are not."""
    return PATH if python_name == "MainThread" or (python_name is None and comm.startswith(_ZMQ_IO)) else NORMAL


def memory_lock_allowed(memlock_limit: int, unlimited: int, can_lock: bool) -> bool:
    """Whether mlockall(MCL_CURRENT | MCL_FUTURE) is safe: with CAP_IPC_LOCK or no RLIMIT_MEMLOCK.
    Under a finite limit MCL_FUTURE would make every later mapping past it fail (a ring, a buffer)."""
    return can_lock or memlock_limit == unlimited


def summary(threads: Iterable[tuple[int, int]]) -> Scheduling:
    """A process's threads' (policy, rt_priority) summed up: the policy of its most urgent thread,
    the real-time priorities in use (highest first), how many threads run real-time, of how many."""
    threads = list(threads)
    rt = sorted({prio for policy, prio in threads if POLICIES.get(policy) in REAL_TIME}, reverse=True)
    policies = [POLICIES.get(policy, str(policy)) for policy, _ in threads]
    policy = next((p for p in REAL_TIME if p in policies), policies[0] if policies else None)
    return {
        "policy": policy,
        "priorities": rt,
        "rt_threads": sum(p in REAL_TIME for p in policies),
        "threads": len(threads),
    }


def sched_text(state: Scheduling | None) -> str:
    """A summary as ``fifo 40/39 (5 of 7 threads)`` or ``other``; ``-`` when unknown."""
    if not state or not state.get("policy"):
        return "-"
    if not state.get("priorities"):
        return str(state["policy"])
    prios = "/".join(map(str, state["priorities"]))
    return f"{state['policy']} {prios} ({state['rt_threads']} of {state['threads']} threads)"
