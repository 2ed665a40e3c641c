"""A child process refuses a spec it cannot read, saying why (fxis_shm.service.childspec)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from fxis_shm.service.childspec import ROLES

pytestmark = pytest.mark.integration


@pytest.mark.parametrize("role", sorted(ROLES))
def test_a_child_given_another_version_fails_through_the_handshake(role):
    spec = json.dumps({"role": role, "version": 999, "service": "x"})
    read_fd, write_fd = os.pipe()
    try:
        child = subprocess.run(
            [sys.executable, "-m", ROLES[role].MODULE, spec, str(write_fd)],
            pass_fds=(write_fd,),
            capture_output=True,
            text=True,
            timeout=60,
        )
        os.close(write_fd)
        write_fd = -1
        handshake = os.read(read_fd, 4096).decode()
    finally:
        os.close(read_fd)
        if write_fd >= 0:
            os.close(write_fd)
    assert child.returncode == 2
    assert handshake.startswith("error ") and "version 999" in handshake
    assert "different installs" in child.stderr
