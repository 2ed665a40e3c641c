"""The service's local faces as a second local user sees them (issue 42, docs/security.md's
table): the rings and semaphores in /dev/shm and the camera workers' command sockets are the
service's user's alone. The neighbour is a user made for the test (tests/integration/neighbour.py)."""

from __future__ import annotations

import glob
import os
import stat
import subprocess

import pytest

from fxis_shm.shm import naming

from .conftest import SMALL
from .neighbour import as_user, local_user

pytestmark = pytest.mark.integration

# what the neighbour tries, with the system's Python (ours may sit in a folder it cannot read)
TRY = """
import socket, sys
for path in sys.argv[1:]:
    try:
        if "commands/" in path:
            s = socket.socket(socket.AF_UNIX); s.connect(path); print("OPEN", path)
        else:
            open(path, "r+b"); print("OPEN", path)
    except OSError as exc:
        print("REFUSED", path, exc.errno)
"""


def test_rings_semaphores_and_command_sockets_are_the_services_users_alone(start_service):
    svc = start_service("--camera", f"a=synthetic:fps=20,{SMALL}")
    rings = naming.leftovers(svc.name)
    folder = naming.commands_dir(svc.name)
    sockets = glob.glob(os.path.join(folder, "*"))
    assert any(p.endswith(".ring") for p in rings) and any("sem." in p for p in rings) and sockets
    assert stat.S_IMODE(os.stat(folder).st_mode) == 0o700
    for path in rings:
        if not os.path.isdir(path):
            assert stat.S_IMODE(os.stat(path).st_mode) == 0o600, path
    for path in sockets:
        assert stat.S_IMODE(os.stat(path).st_mode) == 0o600, path
    tried = [p for p in rings if not os.path.isdir(p)] + sockets
    with local_user() as neighbour:
        done = subprocess.run(
            as_user(neighbour, ["/usr/bin/python3", "-c", TRY, *tried]), capture_output=True, text=True, timeout=30
        )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == len(tried) and all(line.startswith("REFUSED") for line in lines), lines
    with svc.client() as client:  # and the service did not notice
        assert client.image("a").camera == "a"
