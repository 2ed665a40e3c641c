"""The error contract of every ``fxis`` command and of ``Client(...)`` (issue 33, docs/cli.md):
each bad input is one line ``fxis COMMAND: ...`` on stderr naming what to change, no
traceback, the documented exit code, and nothing left behind.

The table runs the commands in this process (``fxis_shm.cli.main.main``), since none of these
inputs may reach a service; the few cases that need one answering (a full disk under ``grab``,
a camera it does not have) start a real service."""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import signal
import socket
import subprocess
import sys

import pytest

from fxis_shm import (
    BadEndpoint,
    Client,
    EventPublisher,
    FxisError,
    InvalidArgument,
    Overrun,
    Overwritten,
    RequestTimeout,
    Subscriber,
)
from fxis_shm.cli import exitcodes
from fxis_shm.cli.main import main, parser
from fxis_shm.errors import Code, service_error
from fxis_shm.shm import naming

from .conftest import SMALL, mounted_tmpfs

pytestmark = pytest.mark.integration

USAGE, NO_SERVICE, FAILED = exitcodes.USAGE, exitcodes.NO_SERVICE, exitcodes.FAILED
NOWHERE = "tcp://127.0.0.1:9"  # discard: nothing answers there
NO_SCHEME = ["127.0.0.1:6500", "localhost:6500"]
BAD_PORTS = ["tcp://127.0.0.1:99999", "tcp://127.0.0.1", "tcp://127.0.0.1:http", "tcp://127.0.0.1:0"]
UNKNOWN_HOST = "tcp://no-such-host.invalid:6500"


def commands() -> set[str]:
    """Every subcommand the parser has."""
    (sub,) = [a for a in parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return set(sub.choices)


@pytest.fixture
def read_only(tmp_path):
    with mounted_tmpfs(tmp_path / "ro", "ro,size=1m") as path:
        yield path


@pytest.fixture
def full_disk(tmp_path):
    """A 256 KiB tmpfs with no byte free."""
    with mounted_tmpfs(tmp_path / "full", "size=256k") as path:
        with open(path / "filler", "wb", buffering=0) as f, contextlib.suppress(OSError):
            while True:
                f.write(b"\0" * 4096)
        yield path


def run_fxis(capsys, argv: list[str]) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line(err: str, command: str, *fragments: str) -> None:
    """The contract's line: one, ``fxis COMMAND: ...``, no traceback, saying ``fragments``."""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"fxis {command}: "), err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


def files_under(folder) -> list[str]:
    """Every file and folder under ``folder``."""
    return sorted(os.path.relpath(os.path.join(top, n), folder) for top, ds, fs in os.walk(folder) for n in ds + fs)


# ---- the table: command x bad input ----

# they take --endpoint, --timeout and keys
CLIENT_COMMANDS = ["status", "grab", "record", "snapshot", "get", "set", "sync-report"]
OUT_COMMANDS = ["grab", "record", "snapshot"]  # they take --out, a folder to create


POSITIONAL = {"get": ["cam0"], "set": ["cam0", "gain=1"]}  # a well-formed rest: the mistake is elsewhere


def with_out(command: str, out: str) -> list[str]:
    return [command, "--out", out] if command in OUT_COMMANDS else [command, *POSITIONAL.get(command, [])]


TMP = "{tmp}"  # the test's own folder, put in when a case runs
NEW = f"{TMP}/new"  # a good --out: the mistake is elsewhere, and the folder must not appear
KEY = f"{TMP}/notakey.key"  # a file that is not a key file


def table() -> list[tuple[list[str], int, tuple[str, ...]]]:
    """(argv, exit code, what the line must say) of each bad input of each command."""
    rows = []
    for command in CLIENT_COMMANDS:
        base = with_out(command, NEW)
        for endpoint in NO_SCHEME:
            rows.append(([*base, "--endpoint", endpoint], USAGE, ("expected tcp://HOST:PORT", f"tcp://{endpoint}")))
        for endpoint in BAD_PORTS:
            rows.append(([*base, "--endpoint", endpoint], USAGE, (endpoint, "port from 1 to 65535")))
        rows.append(([*base, "--endpoint", UNKNOWN_HOST], USAGE, ("not known here",)))
        for timeout in ("-1", "nan", "0", "inf"):
            rows.append(([*base, "--timeout", timeout], USAGE, ("--timeout", "seconds > 0")))
        rows.append(([*base, "--server-key", KEY, "--client-key", KEY], USAGE, ("cannot read the key file", KEY)))
        rows.append(([*base, "--server-key", KEY], USAGE, ("--client-key",)))
    for command in OUT_COMMANDS:
        rows += [
            ([command, "--out", "/proc/x", "--endpoint", NOWHERE], USAGE, ("--out /proc/x", "cannot write there")),
            ([command, "--out", f"{TMP}/no/x", "--endpoint", NOWHERE], USAGE, ("does not exist",)),
        ]
    rows += [
        (["grab", "--out", NEW, "--at", "-5"], USAGE, ("--at", ">= 0")),
        (["snapshot", "--out", NEW, "--before", "-1"], USAGE, ("--before", "seconds >= 0")),
        (["snapshot", "--out", NEW, "--after", "nan"], USAGE, ("--after", "seconds >= 0")),
        (["snapshot", "--out", NEW, "--at", "-5"], USAGE, ("--at", ">= 0")),
        (["record", "--out", NEW, "--seconds", "-1"], USAGE, ("--seconds", "> 0")),
        (["record", "--out", NEW, "--seconds", "nan"], USAGE, ("--seconds", "> 0")),
        (["record", "--out", NEW, "--frames", "-1"], USAGE, ("--frames", ">= 1")),
        (["record", "--out", NEW, "--rate", "nan"], USAGE, ("--rate", "> 0")),
        (["record", "--out", NEW, "--encoding", "jpeg", "--quality", "0"], USAGE, ("--quality",)),
        (["record", "--recover", f"{TMP}/nobag"], USAGE, ("nobag",)),
        (["snapshot", "--out", NEW, "--codec", "vp8"], USAGE, ("--codec vp8: unknown", "h264, h265, av1")),
        (["snapshot", "--out", NEW, "--crf", "20"], USAGE, ("--crf", "give --codec")),
        (["export", f"{TMP}/nobag", "--camera", "a", "--out", f"{TMP}/a.mp4"], USAGE, ("no bag at", "nobag")),
        (["export", f"{TMP}/nobag", "--rerun", f"{TMP}/a.rrd"], USAGE, ("no bag at", "nobag")),
        (["view", NOWHERE], USAGE, ("--rerun", "required")),
        (["view", "--rerun", "--tuples", "0"], USAGE, ("--tuples", ">= 1")),
        (["view", "--rerun", "--rate", "nan"], USAGE, ("--rate", "a number of Hz > 0")),
        (["view", "--rerun", "127.0.0.1:6500"], USAGE, ("ENDPOINT", "expected tcp://HOST:PORT")),
        (["view", NOWHERE, "--rerun", "--rerun-save", "/proc/x/a.rrd"], USAGE, ("--rerun-save", "does not exist")),
        (["view", NOWHERE, "--rerun", "--rerun-save", f"{TMP}/a.rrd", "--rerun-connect", "x"], USAGE, ("give one",)),
        (["keys", "--out", "/proc/x"], USAGE, ("/proc/x", "give a folder")),
        (["cameras", "--timeout", "-1"], USAGE, ("--timeout", "seconds > 0")),
        (["cameras", "--timeout", "nan"], USAGE, ("--timeout", "seconds > 0")),
        (["clean", "--name", "a/b"], USAGE, ("--name", "invalid")),
        (["dashboard", "tcp://127.0.0.1:6500", "--timeout", "nan"], USAGE, ("--timeout", "seconds > 0")),
        (["dashboard", NOWHERE, "--server-key", KEY, "--client-key", KEY], USAGE, ("cannot read the key file",)),
        (["dashboard", NOWHERE, NOWHERE], USAGE, ("given twice",)),
        (["dashboard", UNKNOWN_HOST], USAGE, ("not known here",)),
        (["run", "--slots", "-1"], USAGE, ("slots",)),
        (["run", "--history", "nan"], USAGE, ("history",)),
        (["run", "--foxglove-rate", "-1"], USAGE, ("foxglove_rate",)),
        (["run", "--restart-limit", "-1"], USAGE, ("restart_limit",)),
        (["run", "--port-base", "-5"], USAGE, ("port_base",)),
        (["run", "--camera", "a=synthetic:fps=nan"], USAGE, ("fps",)),
        (["run", "--curve-secret", KEY, "--curve-clients", TMP], USAGE, ("cannot read the key file",)),
        (["run", "--endpoint", "127.0.0.1:6500"], USAGE, ("expected tcp://HOST:PORT",)),
        (["run", "--endpoint", "tcp://127.0.0.1:99999"], USAGE, ("port from 0 to 65535",)),
        (["no-such-command"], USAGE, ("invalid choice",)),
        (["set", "cam0", "gain"], USAGE, ("KEY=VALUE",)),
        (["sync-report", "--seconds", "-1"], USAGE, ("--seconds", "seconds > 0", "'-1'")),
        (["sync-report", "--rate", "nan"], USAGE, ("--rate", "a number of Hz > 0", "'nan'")),
        (["sync-report", "--threshold-ms", "0"], USAGE, ("--threshold-ms", "ms > 0")),
        (["sync-report", "--min-synced-pct", "150"], USAGE, ("--min-synced-pct", "a percentage >= 0 and at most 100")),
        (["sync-report", "--max-dropped-pct", "-1"], USAGE, ("--max-dropped-pct", "a percentage >= 0 and at most 100")),
        (["sync-report", NOWHERE, "--plot", f"{TMP}/out.jpg"], USAGE, ("--plot", "a path ending in .png")),
        (["sync-report", NOWHERE, "--json", "/proc/x/r.json"], USAGE, ("--json /proc/x/r.json", "cannot write")),
        (["sync-report", "127.0.0.1:6500"], USAGE, ("ENDPOINT", "expected tcp://HOST:PORT")),
        (["sync-report", UNKNOWN_HOST], USAGE, ("not known here",)),
    ]
    rows += [(["dashboard", endpoint], USAGE, ("expected tcp://HOST:PORT",)) for endpoint in NO_SCHEME]
    rows += [(["dashboard", endpoint], USAGE, ("port from 1 to 65535",)) for endpoint in BAD_PORTS]
    return rows


TABLE = table()


def test_the_table_covers_every_command():
    covered = {argv[0] for argv, _, _ in TABLE}
    assert commands() <= covered, commands() - covered


@pytest.mark.parametrize(("argv", "code", "fragments"), TABLE, ids=[" ".join(argv) for argv, _, _ in TABLE])
def test_a_bad_input_is_one_line_with_its_code_and_leaves_nothing(argv, code, fragments, tmp_path, capsys):
    """In this process: none of these reaches a service or starts anything."""
    (tmp_path / "notakey.key").write_text("this is not a key file\n")
    argv = [a.replace(TMP, str(tmp_path)) for a in argv]
    fragments = [f.replace(TMP, str(tmp_path)) for f in fragments]
    name = f"errs{os.getpid()}"
    if argv[0] == "run":
        argv = [*argv, "--name", name, "--http", "off"]
    before = files_under(tmp_path)
    try:
        got, out, err = run_fxis(capsys, argv)
    except SystemExit as exc:  # argparse's usage errors end in SystemExit(2)
        got, (out, err) = exc.code, capsys.readouterr()
    assert got == code, err
    if argv[0] in commands():
        assert_one_line(err, argv[0], *fragments)
    else:  # no command: the line is the parser's own
        assert err.startswith("fxis: ") and len(err.strip().splitlines()) == 1, err
    assert out == ""
    assert files_under(tmp_path) == before  # no --out, no partial, no probe left
    assert naming.leftovers(name) == []


def test_an_existing_folder_that_is_not_empty_is_code_2_for_every_command_that_writes_one(tmp_path, capsys):
    """Finding 14: the same code (2) for snapshot, record and grab; the folder is untouched."""
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("mine")
    for command in OUT_COMMANDS:
        code, out, err = run_fxis(capsys, [command, "--out", str(full), "--endpoint", NOWHERE])
        assert code == USAGE
        assert_one_line(err, command, f"--out {full}", "not an empty folder")
        assert os.listdir(full) == ["keep.txt"] and (full / "keep.txt").read_text() == "mine"


def test_a_read_only_out_is_code_2_and_leaves_nothing(read_only, capsys):
    """Finding 3, a read-only disk: refused before any service is asked."""
    for command in OUT_COMMANDS:
        code, out, err = run_fxis(capsys, [command, "--out", str(read_only / "x"), "--endpoint", NOWHERE])
        assert code == USAGE
        assert_one_line(err, command, "--out", "Read-only file system")
        assert os.listdir(read_only) == []
    code, _, err = run_fxis(capsys, ["keys", "--out", str(read_only / "keys")])
    assert code == USAGE and "Read-only file system" in err and os.listdir(read_only) == []


def test_keys_refuses_to_replace_a_pair_unless_forced(tmp_path, capsys):
    """Finding 13: every copy of a pair handed out would stop working."""
    folder = str(tmp_path / "k")
    assert run_fxis(capsys, ["keys", "--out", folder, "--name", "server"])[0] == 0
    before = {f: (tmp_path / "k" / f).read_bytes() for f in os.listdir(folder)}
    code, out, err = run_fxis(capsys, ["keys", "--out", folder, "--name", "server"])
    assert code == USAGE
    assert_one_line(err, "keys", "server.key", "--force")
    assert {f: (tmp_path / "k" / f).read_bytes() for f in os.listdir(folder)} == before
    assert run_fxis(capsys, ["keys", "--out", folder, "--name", "server", "--force"])[0] == 0
    assert (tmp_path / "k" / "server.key").read_bytes() != before["server.key"]


def test_keys_refuses_a_name_that_is_a_path(tmp_path, capsys):
    """Issue 42 finding 8: ``--name ../evil`` wrote the secret key outside --out."""
    folder = tmp_path / "k"
    for name in ("../evil", "a/b", "..", "/tmp/evil", ""):
        code, _, err = run_fxis(capsys, ["keys", "--out", str(folder), "--name", name])
        assert code == USAGE, name
        assert_one_line(err, "keys", "--name", "invalid")
    assert os.listdir(tmp_path) == []  # neither the folder nor ../evil.key


def test_debug_shows_the_traceback(capsys, monkeypatch):
    code, _, err = run_fxis(capsys, ["--debug", "status", "--endpoint", "127.0.0.1:6500"])
    assert code == USAGE and "Traceback" in err and err.strip().splitlines()[-1].startswith("fxis status: ")
    code, _, err = run_fxis(capsys, ["status", "--endpoint", "127.0.0.1:6500", "--debug"])
    assert code == USAGE and "Traceback" in err
    monkeypatch.setenv("FXIS_DEBUG", "1")
    code, _, err = run_fxis(capsys, ["status", "--endpoint", "127.0.0.1:6500"])
    assert code == USAGE and "Traceback" in err


def test_a_service_that_does_not_answer_is_code_3(capsys):
    code, out, err = run_fxis(capsys, ["status", "--endpoint", NOWHERE, "--timeout", "0.2"])
    assert code == NO_SERVICE
    assert_one_line(err, "status", "no reply", "is the service running?")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_or_sigterm_is_code_130_with_one_line(sig):
    """A real signal while ``fxis status`` waits for a reply from a listener that never answers
    (it accepted the connection: the command is past its start, in its request)."""
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(1)
        port = listener.getsockname()[1]
        proc = subprocess.Popen(
            [
                sys.executable,
                "-X",
                "faulthandler",  # SIGABRT prints where each thread stands (below, if it does not end)
                "-m",
                "fxis_shm.cli",
                "status",
                "--endpoint",
                f"tcp://127.0.0.1:{port}",
                "--timeout",
                "60",
            ],
            stderr=subprocess.PIPE,
            text=True,
            # Ctrl-C as a terminal delivers it: a suite started in the background (`make test &`)
            # has SIGINT ignored, and a command started so keeps ignoring it (as Python and
            # POSIX shells do, on purpose), which is not what this asks
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        try:
            listener.settimeout(30)
            peer, _ = listener.accept()  # the client is connected: in the command, past its imports
            proc.send_signal(sig)
            try:
                _, err = proc.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                proc.send_signal(signal.SIGABRT)
                stood = proc.communicate()[1]
                raise AssertionError(f"not ended 30 s after {sig.name}; where it stood:\n{stood}") from None
            peer.close()
        finally:
            proc.kill()
            proc.wait()
    assert proc.returncode == exitcodes.INTERRUPTED
    assert_one_line(err, "status", "interrupted")


# ---- what needs a service answering ----


@pytest.fixture(scope="module")
def service():
    from .conftest import module_service

    yield from module_service(["--camera", "a=synthetic:fps=50,width=320,height=240"])  # 3.8 MB/s raw


def test_grab_on_a_full_disk_is_code_4_and_leaves_no_partial_file(service, full_disk, capsys):
    out = full_disk / "tuple"
    code, stdout, err = run_fxis(capsys, ["grab", "--endpoint", service.endpoint, "--out", str(out)])
    assert code == FAILED
    assert_one_line(err, "grab", "No space left on device", "free some room")
    # what was written whole stays (nothing deletes data), nothing half-written does
    assert all(name.endswith(".png") for name in (os.listdir(out) if out.exists() else [])), os.listdir(out)


def test_a_camera_the_service_does_not_have_is_code_2(service, tmp_path, capsys):
    argv = ["grab", "--endpoint", service.endpoint, "--out", str(tmp_path / "g"), "--cameras", "zz"]
    code, _, err = run_fxis(capsys, argv)
    assert code == USAGE
    assert_one_line(err, "grab", "UNKNOWN_CAMERA")
    assert os.listdir(tmp_path) == []


# ---- the library: Client(...) and client.snapshot(out=...) ----


@pytest.mark.parametrize("endpoint", [*NO_SCHEME, *BAD_PORTS, "udp://127.0.0.1:5", "", "tcp://*:5555"])
def test_client_refuses_an_endpoint_of_another_form(endpoint):
    """Finding 4: an FxisError naming the form, not zmq.error.ZMQError; the streams' sockets too."""
    makers = (Client, lambda e: Client([NOWHERE, e]), Subscriber, EventPublisher)
    for make in makers:
        with pytest.raises(BadEndpoint) as info:
            make(endpoint)
        assert isinstance(info.value, InvalidArgument) and "tcp://HOST:PORT" in str(info.value)


@pytest.mark.parametrize("timeout", [-1, 0, math.nan, math.inf, "3"])
def test_client_refuses_a_timeout_that_is_not_seconds(timeout):
    with pytest.raises(InvalidArgument, match="timeout must be seconds > 0"):
        Client(NOWHERE, timeout=timeout)


def test_client_names_an_unknown_host_when_nothing_answers():
    with Client(UNKNOWN_HOST, timeout=0.2) as client, pytest.raises(RequestTimeout, match="not known here"):
        client.status()


def test_client_snapshot_into_a_path_it_cannot_write_raises_an_fxis_error(service, tmp_path, read_only):
    """Finding 3: the library's error is an FxisError (InvalidArgument), nothing is left."""
    with service.client() as client:
        for out in ("/proc/x", str(tmp_path / "no" / "x"), str(read_only / "x")):
            with pytest.raises(InvalidArgument, match="out "):
                client.snapshot(out=out, before=0.1, after=0)
    assert not os.path.exists("/proc/x") and not (tmp_path / "no").exists() and os.listdir(read_only) == []


# ---- finding 16: an overrun is a code of its own ----


def test_an_overrun_reply_is_its_own_error_with_a_hint_and_the_dashboard_says_503():
    from fxis_shm.core.engine import OVERRUN_MESSAGE
    from fxis_shm.viewers.dashboard import _error

    assert Code.OVERRUN in Code.ALL
    exc = service_error(Code.OVERRUN, OVERRUN_MESSAGE)
    assert isinstance(exc, Overrun) and isinstance(exc, Overwritten) and isinstance(exc, FxisError)
    assert "--history" in str(exc) and "slots" in str(exc)
    answer = _error(exc)
    assert answer.status == 503 and "OVERRUN" in answer.text and "--history" in answer.text
    assert exitcodes.for_error(exc) == FAILED


# ---- finding 18: the words of fxis run ----


def test_the_dev_shm_refusal_suggests_the_size_needed(capsys, tmp_path):
    name = f"shm{os.getpid()}"
    anywhere = ["--endpoint", "tcp://127.0.0.1:0", "--pub", f"ipc://{tmp_path}/p", "--events", f"ipc://{tmp_path}/e"]
    code, _, err = run_fxis(
        capsys,
        ["run", "--name", name, "--http", "off", *anywhere, "--camera", "a=synthetic:fps=30", "--history", "3600"],
    )
    assert code == USAGE and "size=4G" not in err
    line = err.strip()
    needed_mib = float(re.search(r"the rings need ([\d,]+) MiB", line)[1].replace(",", ""))
    stats = os.statvfs(naming.SHM_DIR)
    memory = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    sized = re.search(r"size=(\d+)G|would need (\d+) GiB", line)
    assert sized, line
    gib = int(sized[1] or sized[2])
    used_mib = (stats.f_blocks - stats.f_bfree) * stats.f_frsize / 2**20
    assert (gib - 1) * 1024 < needed_mib + used_mib <= gib * 1024 + 1
    assert ("more than this host's" in line) == (gib * 2**30 > memory)
    assert naming.leftovers(name) == []


def test_record_refuses_a_disk_that_cannot_hold_a_few_seconds(service, tmp_path, capsys):
    """Finding 18: 4 MiB free holds the bag's reserve but about a second of this camera; the
    recording used to start, and stop with what fitted. Nothing is made there."""
    with mounted_tmpfs(tmp_path / "small", "size=4m") as small:
        code, out, err = run_fxis(capsys, ["record", "--endpoint", service.endpoint, "--out", str(small / "bag")])
        assert code == FAILED  # as a snapshot's bag with no room to start (docs/cli.md)
        assert_one_line(err, "record", f"--out {small / 'bag'}", "MB free there holds", "record elsewhere")
        assert os.listdir(small) == [] and out == ""


def test_the_run_banner_shows_each_cameras_history(start_service, tmp_path, wait):
    """Finding 18: ``--history 5`` is every camera's unless its own history= says otherwise;
    the banner said ``history=None``."""
    from .test_viewer_access import printing_to

    out = tmp_path / "banner.txt"
    start_service(
        "--camera",
        f"a=synthetic:fps=20,{SMALL}",
        "--camera",
        f"b=synthetic:fps=20,history=2,{SMALL}",
        "--history",
        "5",
        wrapper=printing_to(out),
    )
    banner = wait(
        lambda: "Ctrl-C stops" in (text := out.read_text() if out.exists() else "") and text,
        timeout=30,
        what="the banner",
    )
    lines = {
        line.split()[0]: line for line in banner.splitlines() if line.startswith("  a ") or line.startswith("  b ")
    }
    assert "None" not in banner
    assert re.search(r"history=5(\.0)?\b", lines["a"]) and re.search(r"history=2(\.0)?\b", lines["b"]), banner


def test_the_slow_path_is_said_only_where_the_hot_path_runs(monkeypatch, caplog, capsys):
    """Finding 18: without a compiled hot path, importing fxis_shm (every command, ``fxis
    status`` included) said so; now ``fxis run`` and a client reading the rings on the
    service's host say it, once."""
    from fxis_shm import _compiled

    monkeypatch.setattr(_compiled, "status", lambda: {"fxis_shm.core.engine": False})
    monkeypatch.setattr(_compiled, "PURE", False)
    monkeypatch.setattr(_compiled, "_warned", False)
    with caplog.at_level("WARNING", logger="fxis_shm"):
        assert _compiled.check() is False
        assert run_fxis(capsys, ["status", "--endpoint", NOWHERE, "--timeout", "0.1"])[0] == NO_SERVICE
        assert caplog.records == [] and "slow path" not in capsys.readouterr().err
        _compiled.warn_slow_path()
        _compiled.warn_slow_path()
    assert [r.getMessage() for r in caplog.records] == [_compiled.slow_path_line()]
    assert "fxis_shm.core.engine" in _compiled.slow_path_line()
