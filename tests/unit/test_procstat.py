import os
import subprocess
import sys

from fxis_shm.shm import procstat


def test_this_process_reads_as_running_with_its_parent():
    me = procstat.read(os.getpid())
    assert me.running and me.ppid == os.getppid() and me.cpu_ticks >= 0
    with open("/proc/self/cmdline", "rb") as f:  # a test runner may retitle itself: read what it shows
        assert procstat.cmdline(os.getpid()) == f.read().decode().split("\0")[:-1]
    with open("/proc/self/comm") as f:
        assert me.name == f.read().rstrip("\n")


def test_a_name_with_spaces_and_parentheses_reads_whole():
    name_it = "import ctypes; ctypes.CDLL(None).prctl(15, b'a (b) c', 0, 0, 0)"
    script = f"{name_it}; import time; print(1, flush=True); time.sleep(30)"
    child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE)
    try:
        child.stdout.readline()  # named by now
        stat = procstat.read(child.pid)
        assert stat.name == "a (b) c" and stat.ppid == os.getpid() and stat.running
    finally:
        child.kill()
        child.wait()


def test_a_child_is_found_and_a_reaped_one_is_gone():
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert child.pid in [c.pid for c in procstat.children(os.getpid())]
        assert child.pid in procstat.descendants(os.getpid())
        assert procstat.cmdline(child.pid) == [sys.executable, "-c", "import time; time.sleep(30)"]
    finally:
        child.kill()
        child.wait()
    assert procstat.read(child.pid) is None and procstat.cmdline(child.pid) == []


def test_a_zombie_does_not_count_as_running():
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    try:
        os.waitid(os.P_PID, child.pid, os.WEXITED | os.WNOWAIT)  # dead, not reaped
        assert procstat.read(child.pid).running is False
    finally:
        child.wait()
