"""The service lock against a hostile neighbour (issue 42, finding 3; fxis_shm/service/servicelock.py):
a second local user, made here with ``useradd`` and removed afterwards, plants a symlink where the
lock used to be and holds an flock on its name; root's ``fxis run`` neither writes through the
symlink nor is kept from starting. A user's own lock folder is theirs alone, and one another
user made or planted is refused. Two supervisors of one name never both hold the lock."""

import os
import pwd
import shutil
import stat
import subprocess
import sys
import tempfile

import pytest

from fxis_shm.service import servicelock

from ..conftest import assert_unlocked, fxis, wait_until
from .conftest import SMALL

pytestmark = pytest.mark.integration

CAMERA = ("--camera", f"a=synthetic:{SMALL}")


class Neighbour:
    """A second local user, and the processes started as it."""

    def __init__(self, name: str):
        user = pwd.getpwnam(name)
        self.name, self.uid, self.gid = name, user.pw_uid, user.pw_gid
        self.started: list[subprocess.Popen] = []

    def run(self, *command: str) -> subprocess.Popen:
        """``command`` run as this user (no session, no PAM: setpriv execs it as the user)."""
        proc = subprocess.Popen(
            ["setpriv", f"--reuid={self.uid}", f"--regid={self.gid}", "--clear-groups", *command],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        self.started.append(proc)
        return proc


@pytest.fixture(scope="module")
def neighbour():
    """A second local user, made for these tests and removed afterwards with every process
    started as it. Fails, saying why, where users cannot be made (not root)."""
    if os.geteuid() != 0 or shutil.which("useradd") is None:
        pytest.fail("the lock tests make a second local user: they need root and useradd", pytrace=False)
    name = f"fxlk{os.getpid()}"
    made = subprocess.run(
        ["useradd", "--system", "--no-create-home", "--shell", "/usr/sbin/nologin", "--user-group", name],
        capture_output=True,
        text=True,
    )
    assert made.returncode == 0, made.stderr
    user = Neighbour(name)
    try:
        yield user
    finally:
        for proc in user.started:
            proc.kill()
            proc.wait()
        removed = subprocess.run(["userdel", name], capture_output=True, text=True)
        subprocess.run(["groupdel", name], capture_output=True, check=False)  # where userdel keeps the group
        shutil.rmtree(os.path.join(tempfile.gettempdir(), f"fxis-{user.uid}"), ignore_errors=True)
        assert removed.returncode == 0, removed.stderr


def in_process_as(user: Neighbour, work) -> str:
    """``work()`` run in a fork of this process turned into ``user`` (its modules loaded already:
    the user need not read this venv). Returns what it returned, or the error's class and message."""
    uid, gid = user.uid, user.gid
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read_fd)
        try:
            os.setgroups([])
            os.setresgid(gid, gid, gid)
            os.setresuid(uid, uid, uid)
            answer = str(work())
        except BaseException as exc:
            answer = f"{type(exc).__name__}: {exc}"
        os.write(write_fd, answer.encode())
        os._exit(0)
    os.close(write_fd)
    with os.fdopen(read_fd) as answer:
        text = answer.read()
    os.waitpid(pid, 0)
    return text


def locked(path: str) -> bool:
    """Whether someone holds an flock on ``path`` (looked at by root, who may open it)."""
    import fcntl

    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return False
    except BlockingIOError:
        return True
    finally:
        os.close(fd)


def test_roots_lock_is_in_a_folder_only_root_may_enter(start_service):
    svc = start_service(*CAMERA)
    path = servicelock.lock_path(svc.name)
    assert os.path.dirname(path) == servicelock.ROOT_FOLDER
    folder, lock = os.lstat(servicelock.ROOT_FOLDER), os.lstat(path)
    assert (folder.st_uid, stat.S_IMODE(folder.st_mode)) == (0, 0o700)
    assert (lock.st_uid, stat.S_IMODE(lock.st_mode), stat.S_ISREG(lock.st_mode)) == (0, 0o600, True)
    assert locked(path)


def test_a_symlink_another_user_planted_is_not_written_through(start_service, neighbour, tmp_path):
    precious = tmp_path / "precious"
    precious.write_text("root's own file\n")
    name = f"sym{os.getpid()}"
    planted = os.path.join(tempfile.gettempdir(), f"fxis-{name}.lock")  # where the lock was
    ln = neighbour.run("ln", "-s", str(precious), planted)
    assert ln.wait(10) == 0, ln.stdout.read()
    try:
        svc = start_service(*CAMERA, name=name)
        with svc.client() as client:
            assert client.status()["cameras"]["a"]["alive"]
        assert precious.read_text() == "root's own file\n"
        assert os.readlink(planted) == str(precious)  # not replaced either
    finally:
        os.remove(planted)


def test_another_users_flock_on_the_name_does_not_keep_roots_service_from_starting(start_service, neighbour):
    name = f"squat{os.getpid()}"
    squatted = os.path.join(tempfile.gettempdir(), f"fxis-{name}.lock")
    squatter = neighbour.run("flock", "--no-fork", "--nonblock", squatted, "sleep", "600")
    try:
        wait_until(lambda: os.path.exists(squatted) and locked(squatted), what="the neighbour's flock")
        into = neighbour.run("touch", os.path.join(servicelock.ROOT_FOLDER, f"fxis-{name}.lock"))
        assert into.wait(10) != 0, "the neighbour could make a file in root's lock folder"
        svc = start_service(*CAMERA, name=name)
        with svc.client() as client:
            assert client.status()["cameras"]["a"]["alive"]
    finally:
        squatter.kill()
        os.remove(squatted)


def test_a_symlink_in_the_lock_folder_is_refused_not_followed(tmp_path):
    precious = tmp_path / "precious"
    precious.write_text("kept\n")
    name = f"link{os.getpid()}"
    path = servicelock.lock_path(name)
    os.symlink(precious, path)
    try:
        result = fxis("run", "--name", name, *CAMERA, "--http", "off")
    finally:
        os.remove(path)
    assert result.returncode == 2, result.stderr
    assert f"lock file {path} is a symlink" in result.stderr and len(result.stderr.splitlines()) == 1
    assert precious.read_text() == "kept\n"


def test_a_users_lock_folder_is_made_theirs_alone(neighbour):
    uid = neighbour.uid
    folder = os.path.join(tempfile.gettempdir(), f"fxis-{uid}")
    shutil.rmtree(folder, ignore_errors=True)

    def take_and_let_go():
        lock = servicelock.ServiceLock("mine")
        lock.release()
        return lock.path

    assert in_process_as(neighbour, take_and_let_go) == os.path.join(folder, "fxis-mine.lock")
    info, lock = os.lstat(folder), os.lstat(os.path.join(folder, "fxis-mine.lock"))
    assert (info.st_uid, stat.S_IMODE(info.st_mode), stat.S_ISDIR(info.st_mode)) == (uid, 0o700, True)
    assert (lock.st_uid, stat.S_IMODE(lock.st_mode)) == (uid, 0o600)


@pytest.mark.parametrize("planted", ["another user's folder", "a symlink", "a folder open to all"])
def test_a_lock_folder_not_the_users_alone_is_refused(neighbour, tmp_path, planted):
    uid, gid = neighbour.uid, neighbour.gid
    folder = os.path.join(tempfile.gettempdir(), f"fxis-{uid}")
    shutil.rmtree(folder, ignore_errors=True)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir(mode=0o777)
    os.chown(elsewhere, uid, gid)
    if planted == "another user's folder":
        os.mkdir(folder, 0o700)  # root's, standing in for any other user
        expected = f"lock folder {folder} belongs to uid 0, not to this user (uid {uid})"
    elif planted == "a symlink":
        os.symlink(elsewhere, folder)
        expected = f"lock folder {folder} is not a folder (a symlink?)"
    else:
        os.mkdir(folder)
        os.chmod(folder, 0o777)
        os.chown(folder, uid, gid)
        expected = f"lock folder {folder} has mode 0777: chmod 700 it"
    try:
        answer = in_process_as(neighbour, lambda: servicelock.ServiceLock("mine").path)
    finally:
        if os.path.islink(folder):
            os.remove(folder)
        shutil.rmtree(folder, ignore_errors=True)
    assert answer.startswith("LockRefused: " + expected), answer
    assert os.listdir(elsewhere) == []  # nothing made through the symlink


CONTENDER = """
import os, sys, time
from fxis_shm.service.servicelock import AlreadyRunning, ServiceLock
name, marker, rounds = sys.argv[1], sys.argv[2], int(sys.argv[3])
held = refused = both = 0
print("ready", flush=True)
sys.stdin.readline()  # all start at once
deadline = time.monotonic() + 60
while held < rounds and time.monotonic() < deadline:
    try:
        lock = ServiceLock(name)
    except AlreadyRunning:
        refused += 1
        continue
    held += 1
    try:  # only the lock's holder may be here: a marker only one process can make at a time
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        both += 1
    else:
        os.close(fd)
        time.sleep(0.0002)
        os.remove(marker)
    lock.release()
print(held, refused, both)
"""


def test_two_supervisors_of_one_name_never_both_hold_the_lock(tmp_path):
    """Four processes take and let go of one name's lock, 300 times each, as fast as they can:
    whoever holds it makes a marker file only one process can make at a time. Removing the lock
    file on release let a process that opened it before the removal and one that made it again
    both hold it."""
    name, marker = f"race{os.getpid()}", str(tmp_path / "holder")
    contenders = [
        subprocess.Popen(
            [sys.executable, "-c", CONTENDER, name, marker, "300"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        for _ in range(4)
    ]
    try:
        for proc in contenders:
            assert proc.stdout.readline().strip() == "ready"
        for proc in contenders:
            proc.stdin.write("go\n")
            proc.stdin.flush()
        results = [[int(n) for n in proc.communicate(timeout=120)[0].split()] for proc in contenders]
    finally:
        for proc in contenders:
            proc.kill()
            proc.wait()
    assert [held for held, _, _ in results] == [300] * 4, results
    assert sum(refused for _, refused, _ in results) > 0, "they never met: nothing was tested"
    assert sum(both for _, _, both in results) == 0, f"two processes held the lock at once: {results}"
    assert_unlocked(name)


def test_xdg_runtime_dir_holds_the_lock_when_set_and_is_checked_too(tmp_path, monkeypatch):
    runtime = tmp_path / "runtime"
    runtime.mkdir(mode=0o700)
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(runtime))
    lock = servicelock.ServiceLock("xdg")
    try:
        assert lock.path == str(runtime / "fxis-xdg.lock") and servicelock.service_running("xdg")
    finally:
        lock.release()
    assert not servicelock.service_running("xdg")
    runtime.chmod(0o755)
    with pytest.raises(servicelock.LockRefused, match="has mode 0755: chmod 700 it"):
        servicelock.ServiceLock("xdg")
