"""The supervisor's process table is on record before a child it starts can be asked about it: a
coordinator answers status as soon as it is ready, from that table (a SIGKILLed coordinator's
successor once served its predecessor's table, ``restarts`` 0). The children are stand-ins whose
readiness reads the table; the table itself is the real file."""

import itertools
import json
import os
import uuid
from types import SimpleNamespace

import pytest

from fxis_shm.service.config import build_config
from fxis_shm.service.supervisor import Supervisor
from fxis_shm.shm import naming

PIDS = itertools.count(40_000)


@pytest.fixture
def supervisor():
    config = build_config({}, {"cameras": ["a=synthetic", "b=synthetic"], "name": f"table-{uuid.uuid4().hex[:8]}"})
    sup = Supervisor(config)
    seen = {}  # child key -> its row in the table when its readiness was awaited

    def stand_in(child):
        def start():
            child.proc = SimpleNamespace(pid=next(PIDS))

        def wait_ready(timeout=None):
            with open(naming.supervisor_state_path(config.name)) as f:
                seen[child.key] = json.load(f)["processes"][child.key]

        child.start, child.wait_ready = start, wait_ready

    for child in sup.children:
        stand_in(child)
    yield sup, seen
    path = naming.supervisor_state_path(config.name)
    if os.path.exists(path):
        os.unlink(path)


def test_every_child_is_on_record_with_its_pid_before_it_is_ready(supervisor):
    sup, seen = supervisor
    sup._start_all()
    for child in [*sup.cameras, sup.coordinator]:
        assert seen[child.key]["pid"] == child.proc.pid


def test_a_restarted_child_is_on_record_with_its_new_pid_and_count_before_it_is_ready(supervisor):
    sup, seen = supervisor
    sup._start_all()
    old = sup.coordinator.proc.pid
    sup._restart(sup.coordinator)
    assert seen["coordinator"]["pid"] == sup.coordinator.proc.pid != old
    assert seen["coordinator"]["restarts"] == 1
