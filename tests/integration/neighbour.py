"""A second local user for the tests that try the service as a neighbour on its host would
(issue 42): made with ``useradd`` for the test, removed afterwards, its programs run with its
own ids by ``setpriv`` (no root, no group of ours)."""

from __future__ import annotations

import contextlib
import os
import pwd
import subprocess


@contextlib.contextmanager
def local_user():
    """A second local user (no home, no login), removed afterwards whatever happened."""
    name = f"fxisneighbour{os.getpid() % 100000}"
    subprocess.run(["useradd", "--no-create-home", "--shell", "/usr/sbin/nologin", name], check=True)
    try:
        yield pwd.getpwnam(name)
    finally:
        subprocess.run(["userdel", name], check=True)


def as_user(user: pwd.struct_passwd, command: list[str]) -> list[str]:
    """``command`` run as ``user``."""
    return ["setpriv", f"--reuid={user.pw_uid}", f"--regid={user.pw_gid}", "--clear-groups", *command]
