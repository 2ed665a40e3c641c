"""CPU shares of a service's processes, the bench and the host, from /proc: what the
benches that ask "what does this cost the service?" share. Not a public module."""

from __future__ import annotations

import os

from fxis_shm.shm import procstat

BENCH, HOST, IDLE = "bench (client)", "host busy", "host idle"  # CPU rows besides the service's


def service_processes(status: dict, supervisor_pid: int) -> dict[str, int]:
    """name -> pid of every process of the service: the supervisor, what it reports, the rest."""
    procs = {"supervisor": supervisor_pid}
    for name, proc in status["supervisor"]["processes"].items():
        if proc.get("pid"):
            procs[name] = proc["pid"]
    known = set(procs.values())
    for pid in procstat.descendants(supervisor_pid):
        if pid not in known:
            procs[f"other {pid}"] = pid
    return procs


def cpu_ticks(pid: int) -> int | None:
    """utime + stime of ``pid`` (every thread), in clock ticks; None if it is gone."""
    stat = procstat.read(pid)
    return None if stat is None else stat.cpu_ticks


def host_idle_ticks() -> int:
    """Clock ticks all CPUs of the host spent idle (idle + iowait). Busy time is taken as the
    rest: /proc/stat's user and system are sampled on timer ticks and miss periodic work that
    falls between them (4 cameras at 125 fps showed half their CPU), while idle is measured."""
    with open("/proc/stat") as f:
        idle, iowait = (int(v) for v in f.readline().split()[4:6])
    return idle + iowait


def cpu_sample(procs: dict[str, int]) -> dict:
    """CPU ticks so far of every named process, of the bench itself, and the host's idle ticks."""
    sample = {name: cpu_ticks(pid) for name, pid in procs.items()}
    sample[BENCH] = cpu_ticks(os.getpid())
    sample[IDLE] = host_idle_ticks()
    return sample


def cpu_percent(before: dict, after: dict, seconds: float) -> dict:
    """Percent of one core per process over ``seconds`` (None if it died meanwhile)."""
    tick = os.sysconf("SC_CLK_TCK")
    return {
        name: (after[name] - before[name]) / tick / seconds * 100
        if before.get(name) is not None and after.get(name) is not None
        else None
        for name in before
    }
