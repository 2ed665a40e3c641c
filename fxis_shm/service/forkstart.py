"""Starting a camera worker or the coordinator by forking the supervisor, which has their
modules loaded already, rather than in a fresh interpreter.

A fresh ``python -m fxis_shm.workers.camera`` spends some 0.3 CPU-seconds importing numpy,
pyzmq and the package before it opens its camera; a fork of a supervisor that imported them
once spends a few milliseconds. That is every start of a service and, where it matters most,
every restart of a crashed worker. The child is the supervisor's own, as with ``subprocess``:
the supervisor waits for it, sees its exit code and signals it.

The forked child is a copy of the supervisor, so it first sheds what is the supervisor's: its
signal handlers and their wakeup pipe (stopsignals.StopSignals), its stdin (a worker reads none), its open
files but the readiness pipe (the service's lock among them: an orphaned worker must not hold
it), its logging handlers (the child sets its own), and, on the way out, its exit handlers and
``finally`` blocks (``os._exit``: a child unwinding into the supervisor's code would remove the
service's shared memory). The supervisor's objects are frozen out of the child's garbage
collection, so that none is finalized there, closing a file number the child has reused. The
supervisor has no thread but its main one (its signals wake its loop through a pipe), so no
lock is held by a thread the fork leaves behind. ``ps`` and ``top`` show the child's
role in its name (``fxis camera``, ``fxis coord``: /proc/PID/comm); its command line is
the supervisor's.

``FXIS_SPAWN=exec`` starts every child in a fresh interpreter, as before (a profiler, a
debugger attached by command line)."""

from __future__ import annotations

import ctypes
import gc
import importlib
import logging
import os
import select
import signal
import subprocess
import sys
import traceback

_PR_SET_NAME = 15
# what a child resets: the signals the supervisor (StopSignals) and Python itself handle
_SUPERVISOR_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def fork_wanted() -> bool:
    """Whether children the supervisor can fork are forked (``FXIS_SPAWN`` unset or ``fork``)."""
    return os.environ.get("FXIS_SPAWN", "fork").strip().lower() != "exec"


class ForkedProcess:
    """The handle of a forked child, with the part of ``subprocess.Popen``'s interface the
    supervisor uses: ``pid``, ``poll``, ``wait``, ``send_signal``, ``kill``, ``returncode``."""

    def __init__(self, pid: int):
        self.pid = pid
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid == self.pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is not None:
            return self.returncode
        if timeout is not None:
            fd = os.pidfd_open(self.pid)
            try:
                if not select.select([fd], [], [], max(0.0, timeout))[0]:
                    raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout)
            finally:
                os.close(fd)
        _, status = os.waitpid(self.pid, 0)
        self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, sig)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


def fork_child(module: str, argv: list[str], keep_fd: int, title: str) -> ForkedProcess:
    """Fork a child that runs ``module.main()`` with ``sys.argv[1:] == argv``, as
    ``python -m module *argv`` would, keeping ``keep_fd`` (its readiness pipe). The module is
    imported here first, once per supervisor: the child inherits it loaded."""
    main = importlib.import_module(module).main
    for stream in (sys.stdout, sys.stderr):  # or the child would write the supervisor's buffered lines again
        stream.flush()
    pid = os.fork()
    if pid:
        return ForkedProcess(pid)
    code = 1
    try:
        _shed_the_supervisor(keep_fd, title)
        sys.argv = [module, *argv]
        main()
        code = 0
    except SystemExit as exc:
        code = _exit_code(exc.code)
    except BaseException:
        traceback.print_exc()
    finally:
        try:
            logging.shutdown()
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)
    raise AssertionError("unreachable")  # os._exit does not return


def _shed_the_supervisor(keep_fd: int, title: str) -> None:
    for sig in _SUPERVISOR_SIGNALS:
        signal.signal(sig, signal.SIG_DFL)
    # before the files close: a signal would write to the wakeup pipe's number, soon another file's
    signal.set_wakeup_fd(-1)
    gc.freeze()
    os.closerange(3, keep_fd)
    os.closerange(keep_fd + 1, os.sysconf("SC_OPEN_MAX"))
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    for handler in logging.root.handlers[:]:
        logging.root.removeHandler(handler)
    try:
        ctypes.CDLL(None).prctl(_PR_SET_NAME, title.encode()[:15], 0, 0, 0)
    except (OSError, AttributeError):
        pass


def _exit_code(code: object) -> int:
    if code is None:
        return 0
    if isinstance(code, int):
        return code
    print(code, file=sys.stderr)
    return 1
