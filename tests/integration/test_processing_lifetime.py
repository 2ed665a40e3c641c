"""Nothing a camera worker starts outlives it (issue 42, finding 5): the processes of its hook
pool (``process_workers=3``) and multiprocessing's resource tracker end however the service or the
worker ends: SIGTERM to the supervisor, kill -9 of the supervisor, kill -9 of the camera worker,
with the worker forked or started fresh (FXIS_SPAWN=exec)."""

import os
import signal

import pytest

from fxis_shm.shm import procstat

from ..conftest import fxis, wait_until
from .conftest import SMALL, child_pids
from .test_processing import REPO

pytestmark = pytest.mark.integration

HOOKED = ("--camera", f"a=synthetic:fps=20,{SMALL},process=tests.hooks:slow_60ms,process_workers=3")


def alive(pid: int) -> bool:
    stat = procstat.read(pid)
    return stat is not None and stat.running


def pool_of(svc) -> dict[int, str]:
    """The processes camera a's worker started, by pid: its 3 hook processes and the tracker."""
    (worker,) = child_pids(svc, "camera")
    found = {pid: " ".join(procstat.cmdline(pid)) for pid in procstat.descendants(worker)}
    trackers = [pid for pid, line in found.items() if "resource_tracker" in line]
    assert len(found) == 4 and len(trackers) == 1, found  # what the test looks for is there
    return found


@pytest.mark.parametrize("spawn", ["fork", "exec"])
@pytest.mark.parametrize("ending", ["SIGTERM to the supervisor", "kill -9 of the supervisor", "kill -9 of the worker"])
def test_the_hook_pool_ends_with_the_worker(start_service, spawn, ending):
    env = {**os.environ, "FXIS_SPAWN": spawn, "PYTHONPATH": REPO + os.pathsep + os.environ.get("PYTHONPATH", "")}
    svc = start_service(*HOOKED, env=env)
    pool = pool_of(svc)
    if ending == "SIGTERM to the supervisor":
        assert svc.stop() == 0
    elif ending == "kill -9 of the supervisor":
        children = [*child_pids(svc, "camera"), *child_pids(svc, "coordinator")]
        svc.proc.kill()
        svc.proc.wait()
        wait_until(lambda: not any(alive(pid) for pid in children), what="the service's children to exit")
        cleaned = fxis("clean", "--name", svc.name)  # what the next fxis run would do
        assert cleaned.returncode == 0, cleaned.stderr
    else:
        (worker,) = child_pids(svc, "camera")
        os.kill(worker, signal.SIGKILL)
    wait_until(
        lambda: not any(alive(pid) for pid in pool),
        timeout=15,
        what=f"the pool to end: {[line for pid, line in pool.items() if alive(pid)]}",
    )
    if ending == "kill -9 of the worker":  # the supervisor's restart starts a pool of its own
        wait_until(lambda: child_pids(svc, "camera", "running"), timeout=20, what="camera a restarted and ready")
        assert not set(pool_of(svc)) & set(pool)
