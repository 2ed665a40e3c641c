"""The contract on every input, found by a generator rather than a list (issue 43): Hypothesis
draws commands and flag values (numbers at and beyond their ranges, NaN, inf, huge, negative,
unicode and over-long names, odd endpoints incl. IPv6 and long ipc paths, malformed config
files) and checks for each: an exit code of the table (docs/cli.md), at most two lines on
stderr, no traceback, nothing left behind (a file, a process, shared memory), and a bounded
wall time (pytest-timeout is the hang guard; nothing here asserts a speed).

Most draws run the command in this process against ONE shared service; only ``fxis run``'s
draws (flags and config files) spawn a process. The Python API is drawn against the same
service. The seed is fixed (derandomize); FXIS_CONTRACT_EXAMPLES=N runs N examples per
command instead of the suite's few hundred (a developer's longer run):

    FXIS_CONTRACT_EXAMPLES=5000 .venv/bin/python -m pytest -q -p no:xdist -s \
        tests/integration/test_contract_generator.py

Each test prints the cases it tried per command (``-s`` shows them)."""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from fxis_shm import Client, FxisError
from fxis_shm.cli import exitcodes
from fxis_shm.cli.main import main
from fxis_shm.errors import BadRequest, InvalidArgument, ProtocolError, SettingRejected
from fxis_shm.shm import naming

from . import contractdraws as draws
from .conftest import assert_nothing_left, module_service

pytestmark = [pytest.mark.integration, pytest.mark.timeout(1800)]

EXAMPLES = int(os.environ.get("FXIS_CONTRACT_EXAMPLES", "200"))
CODES = set(exitcodes.MEANINGS)
TRIED: Counter = Counter()  # cases per command, printed at the end of each test


def examples(n: int) -> settings:
    return settings(
        max_examples=n,
        derandomize=True,  # a fixed seed: the same cases on every run
        deadline=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large],
    )


@pytest.fixture(scope="module")
def service():
    yield from module_service(["--camera", f"{draws.CAMERA}=synthetic:fps=50,width=64,height=48", "--history", "2"])


@pytest.fixture(scope="module", autouse=True)
def said():
    yield
    print("\ncontract generator, cases tried per command:", dict(sorted(TRIED.items())))


def files_under(folder: str) -> list[str]:
    return sorted(os.path.relpath(os.path.join(top, n), folder) for top, ds, fs in os.walk(folder) for n in ds + fs)


def check_lines(err: str, command: str, code: int) -> None:
    """A code of the table, no traceback; a failure says itself in at most two lines, each
    ``fxis COMMAND: ...`` (a command that did its work may report progress: fxis record)."""
    lines = err.strip().splitlines()
    assert "Traceback" not in err, err
    assert "a bug: please report it" not in err, err
    assert code in CODES, (code, err)
    if code not in (exitcodes.DONE, exitcodes.MISSING, exitcodes.SYNC_FAILED):
        assert len(lines) <= 2, err
    assert all(line.startswith(f"fxis {command}") for line in lines), err


def run_in_process(command: str, argv: list[str], endpoint: str) -> tuple[int, str, list[str], list[str]]:
    """``fxis COMMAND argv`` here, in a folder of its own: (code, stderr, files before, files after)."""
    tmp = tempfile.mkdtemp(prefix="fxis-contract-")
    try:
        os.makedirs(f"{tmp}/full")
        with open(f"{tmp}/full/x", "w") as f:
            f.write("x")
        before = files_under(tmp)
        args = [a.replace(draws.TMP, tmp).replace(draws.SERVICE, endpoint) for a in argv]
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), contextlib.chdir(tmp):
            try:
                code = main([command, *args])
            except SystemExit as exc:  # argparse's usage error, or --help
                code = exc.code if isinstance(exc.code, int) else exitcodes.USAGE
        return code, err.getvalue(), before, files_under(tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# what a command may end with when it asked the shared, healthy service: a refusal of what the
# user typed is 2 (the camera refused a value, or has no such setting), never "failed at run time"
USAGE_ONLY = {"get": {0, 2}, "set": {0, 2}}


@pytest.mark.parametrize("command", sorted(draws.COMMANDS))
def test_every_command_keeps_the_contract_on_any_input(command, service):
    @examples(EXAMPLES)
    @given(argv=draws.COMMANDS[command])
    def case(argv):
        TRIED[command] += 1
        code, err, before, after = run_in_process(command, argv, service.endpoint)
        check_lines(err, command, code)
        if code not in (exitcodes.DONE, exitcodes.MISSING):  # a failure leaves nothing behind
            assert after == before, (argv, err, sorted(set(after) - set(before)))
        reached_service = draws.SERVICE in argv and "--timeout" not in argv
        if reached_service and command in USAGE_ONLY:
            assert code in USAGE_ONLY[command], (argv, code, err)

    case()
    with Client(service.endpoint) as client:  # it still serves
        assert client.status()["cameras"][draws.CAMERA]["alive"]
    assert naming.leftovers(f"ctr{os.getpid()}") == []


# ---- the Python API against the same service ----

BAD_TYPES = st.one_of(st.text(max_size=5), st.floats(), st.lists(st.integers(), max_size=2), st.just(object()))
TIMES = st.one_of(st.none(), st.integers(-(2**70), 2**70), st.floats(allow_nan=True), st.just("abc"), st.just(1.5e18))
TIMEOUTS = st.one_of(st.none(), st.floats(max_value=0.3), st.just(float("nan")), st.integers(-5, 0), BAD_TYPES)
CAMERAS = st.one_of(
    st.none(),
    st.just(draws.CAMERA),
    st.lists(draws.names(), max_size=3),
    st.lists(st.integers(), max_size=2),
    BAD_TYPES,
)


def api_calls() -> st.SearchStrategy[tuple[str, dict]]:
    return st.one_of(
        st.fixed_dictionaries({"camera": draws.names(), "at": TIMES, "timeout": TIMEOUTS}).map(lambda k: ("image", k)),
        st.fixed_dictionaries(
            {
                "cameras": CAMERAS,
                "at": TIMES,
                "timeout": TIMEOUTS,
                "max_skew_ms": st.one_of(st.none(), st.floats(allow_nan=True), BAD_TYPES),
            }
        ).map(lambda k: ("tuple", k)),
        st.fixed_dictionaries({"cameras": CAMERAS}).map(lambda k: ("latest", k)),
        st.fixed_dictionaries(
            {
                "kind": st.sampled_from(["consecutive", "interval", "range", "bogus"]),
                "camera": st.one_of(st.none(), draws.names()),
                "count": st.one_of(st.none(), st.integers(-3, 10**9), BAD_TYPES),
                "interval_ms": st.one_of(st.none(), st.floats(allow_nan=True), BAD_TYPES),
                "start": TIMES,
                "end": TIMES,
                "timeout": TIMEOUTS,
            }
        ).map(lambda k: ("sequence", k)),
        st.fixed_dictionaries(
            {
                "camera": draws.names(),
                "values": st.dictionaries(
                    st.sampled_from(draws.SETTING_KEYS[:6]),
                    st.one_of(
                        st.floats(allow_nan=True), st.integers(-(10**20), 10**20), st.text(max_size=4), st.none()
                    ),
                    max_size=2,
                ),
            }
        ).map(lambda k: ("configure", k)),  # fmt: skip
        st.fixed_dictionaries({"camera": st.one_of(draws.names(), BAD_TYPES)}).map(lambda k: ("settings", k)),
        st.fixed_dictionaries({"timeout": TIMEOUTS, "queue": st.one_of(st.integers(-2, 10**7), BAD_TYPES)}).map(
            lambda k: ("subscribe", k)
        ),
        st.fixed_dictionaries(
            {
                "before": st.one_of(st.floats(allow_nan=True), st.integers(-1, 10**6), BAD_TYPES),
                "after": st.one_of(st.floats(max_value=0.2), st.just(float("nan")), st.integers(-1, 0), BAD_TYPES),
                "at": TIMES,
            }
        ).map(lambda k: ("snapshot", k)),
    )


def call(client: Client, op: str, kwargs: dict, tmp: str):
    if op == "configure":
        return client.configure(kwargs["camera"], **kwargs["values"])
    if op == "settings":
        return client.settings(kwargs["camera"])
    if op == "snapshot":
        return client.snapshot(out=f"{tmp}/snap", **kwargs)
    if op == "subscribe":
        with client.subscribe(**kwargs):
            return None
    kind = kwargs.pop("kind", None)
    return getattr(client, op)(*([kind] if kind else []), **kwargs)


@pytest.mark.parametrize("client_timeout", [0.5])
def test_every_bad_argument_of_the_python_api_is_an_fxis_error_named_in_the_docs(service, client_timeout):
    with Client(service.endpoint, timeout=client_timeout) as client:

        @examples(EXAMPLES * 2)
        @given(drawn=api_calls())
        def case(drawn):
            op, kwargs = drawn
            TRIED[f"api.{op}"] += 1
            tmp = tempfile.mkdtemp(prefix="fxis-contract-")
            try:
                call(client, op, dict(kwargs), tmp)
            except FxisError as exc:
                # the client checks what it is given: the service never sees a malformed request
                assert not isinstance(exc, (ProtocolError, BadRequest)), (op, kwargs, exc)
            except Exception as exc:  # noqa: BLE001  (the finding: anything else)
                raise AssertionError(f"{op}({kwargs}) raised {type(exc).__name__}: {exc}") from exc
            finally:
                shutil.rmtree(tmp, ignore_errors=True)

        case()
        assert client.status()["cameras"][draws.CAMERA]["alive"]


def test_client_arguments_of_the_wrong_kind_are_invalid_argument(service):
    """The issue's findings, each once (the generator draws their kind)."""
    with Client(service.endpoint, timeout=1) as client:
        for call_ in (
            lambda: client.tuple(at="abc"),
            lambda: client.tuple(at=1.5e18),
            lambda: client.tuple(cameras="left"),
            lambda: client.tuple(timeout=-1),
            lambda: client.image(draws.CAMERA, at=2**70),
            lambda: client.sequence("consecutive", camera=draws.CAMERA, count=10**9),
            lambda: client.subscribe(queue=0),
        ):
            with pytest.raises(InvalidArgument):
                call_()
        for value in (float("nan"), float("inf")):
            with pytest.raises(SettingRejected):
                client.configure(draws.CAMERA, gain=value)


# ---- fxis run: flags and config files, each a process of its own ----

CONFIG_FILES = [
    b"\xff\xfe\x00n\x00a\x00m\x00e",  # UTF-16, not UTF-8
    b"name = 'x'\n\x80\x81",
    b"[cameras.a]\nkind = 'synthetic'\n[cameras.a]\nkind = 'synthetic'\n",  # a camera twice
    b"slots = 1e9\n",
    b"slots = 99999999999999999999\n",
    b"slots = 'many'\n",
    b"history = nan\n",
    b"history = inf\n",
    b"history = -1\n",
    b"restart_limit = 1e400\n",
    b"cameras = 5\n",
    b"cameras = []\n",
    b"[cameras.x]\nfps = 10\n",
    b"[cameras.'a b']\nkind = 'synthetic'\n",
    b"[cameras.a]\nkind = 'synthetic'\nfps = nan\n",
    b"[cameras.a]\nkind = 'synthetic'\nwidth = 1e12\n",
    b"[cameras.a]\nkind = 'synthetic'\nfps = -1\n",
    b"[cameras.a]\nkind = 'nosuchkind'\n",
    b"endpoint = 'tcp://[::1]:21400'\n",
    b"endpoint = 'ipc:///tmp/" + b"x" * 120 + b"'\n",
    b"endpoint = 5\n",
    b"foxglove_rate = 1e9\n",
    b"port_base = 70000\n",
    b"lockstep = 'nan'\n",
    b"lockstep = '1e9'\n",
    b"clock = 'sundial'\n",
    b"nonsense = true\n",
    b"[client]\nserver_key = 5\n",
    b"=\n",
    b"",
    b"\x00" * 10,
    b"a" * 100_000,
]

RUN_FLAGS = draws.joined(
    draws.flag("--slots", draws.typed_numbers()),
    draws.flag("--history", draws.typed_numbers()),
    draws.flag("--restart-limit", draws.typed_numbers()),
    draws.flag("--endpoint", st.sampled_from(draws.ODD_ENDPOINTS)),
    draws.flag("--foxglove-rate", draws.typed_numbers()),
    draws.flag("--lockstep", draws.typed_numbers()),
    st.lists(
        st.tuples(
            st.sampled_from(["a", "a", "b", "é", "", "a" * 200]), st.sampled_from(["fps=10", "fps=nan", "width=0"])
        ),
        max_size=3,
    ).map(lambda cams: [x for n, o in cams for x in ("--camera", f"{n}=synthetic:{o},height=48")]),
)


def spawn_run(args: list[str], name: str) -> tuple[int, str]:
    """``fxis run`` with ``args``: its code and stderr; one that starts is stopped by SIGINT once
    it is up (a hang guard of a minute, which is not a speed assert)."""
    argv = [sys.executable, "-m", "fxis_shm.cli", "run", "--name", name, "--http", "off", *args]
    with subprocess.Popen(argv, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True) as proc:
        try:
            _, err = proc.communicate(timeout=8)
        except subprocess.TimeoutExpired:  # it started: a valid draw; Ctrl-C
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=60)
            assert proc.returncode == exitcodes.DONE, err
            return proc.returncode, ""
    return proc.returncode, err


@settings(max_examples=int(os.environ.get("FXIS_CONTRACT_RUN_EXAMPLES", "24")), derandomize=True, deadline=None)
@given(
    config=st.one_of(st.none(), st.sampled_from(CONFIG_FILES)),
    flags=RUN_FLAGS,
)
def test_fxis_run_keeps_the_contract_on_any_flags_and_config_file(config, flags):
    TRIED["run"] += 1
    name = f"ctr{os.getpid()}r{TRIED['run']}"
    with tempfile.TemporaryDirectory(prefix="fxis-contract-") as tmp:
        args = [*flags, "--pub", f"ipc://{tmp}/p", "--events", f"ipc://{tmp}/e"]  # never a port another has
        if "--endpoint" not in args and b"endpoint" not in (config or b""):
            args += ["--endpoint", f"ipc://{tmp}/r"]
        if config is not None:
            with open(f"{tmp}/c.toml", "wb") as f:
                f.write(config)
            args += ["--config", f"{tmp}/c.toml"]
        started = time.monotonic()
        code, err = spawn_run(args, name)
        check_lines(err, "run", code)
        assert code in (exitcodes.DONE, exitcodes.USAGE), (args, code, err)
        assert time.monotonic() - started < 120  # a hang guard (the spawn's own timeouts make it so)
        assert os.listdir(tmp) == (["c.toml"] if config is not None else []), os.listdir(tmp)  # no ipc file left
    assert_nothing_left(name)  # shared memory, its lock
    assert processes_named(name) == []


def processes_named(name: str) -> list[int]:
    """The processes whose command line holds ``name`` (a service's workers are forks of it)."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        with contextlib.suppress(OSError):
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                if name.encode() in f.read().split(b"\0"):
                    found.append(int(pid))
    return found
