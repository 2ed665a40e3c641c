"""Issue 43's findings, each once (the generator, test_contract_generator.py, draws their kind):
exit codes as the table says, --timeout kept, a camera never silently lost, one line instead of
a traceback, no unbounded work from one number."""

from __future__ import annotations

import pytest

from fxis_shm import BadEndpoint, Client
from fxis_shm.cli import exitcodes
from fxis_shm.cli.main import main
from fxis_shm.errors import ConfigError
from fxis_shm.service.config import build_config

from .conftest import module_service

pytestmark = pytest.mark.integration

NOWHERE = "tcp://127.0.0.1:9"


@pytest.fixture(scope="module")
def service():
    yield from module_service(["--camera", "left=synthetic:fps=50,width=64,height=48", "--history", "2"])


def one_line(capsys, argv: list[str]) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's usage error
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(f"fxis {argv[0]}: "), err
    return code, err


@pytest.mark.parametrize(
    "assignment",
    ["exposure_us=0", "exposure_us=abc", "gain=30", "foo=1", "width=15", "fps=-1", "gain=nan", "exposure_us=inf"],
)
def test_a_refused_setting_is_code_2(service, capsys, assignment):
    code, err = one_line(capsys, ["set", "left", assignment, "--endpoint", service.endpoint])
    assert code == exitcodes.USAGE, err
    assert assignment.partition("=")[0] in err


def test_get_and_set_keep_their_timeout(capsys):
    for argv in (["get", "left"], ["set", "left", "gain=1"]):
        code, err = one_line(capsys, [*argv, "--endpoint", NOWHERE, "--timeout", "0.5"])
        assert code == exitcodes.NO_SERVICE
        assert "within 0.5 s" in err, err  # not the 10.5 s a settings request may take once answered


def test_two_cameras_of_one_name_are_refused(capsys):
    flags = ["--camera", "a=synthetic:width=64,height=64", "--camera", "a=synthetic:fps=10,width=64,height=64"]
    code, err = one_line(capsys, ["run", *flags])
    assert code == exitcodes.USAGE and "'a' is given twice" in err
    with pytest.raises(ConfigError, match="given twice"):
        build_config({}, {"cameras": ["a=synthetic", "a=synthetic"]})
    # a flag still replaces the config file's camera of its name (docs: flags override the file)
    config = build_config({"cameras": {"a": {"kind": "synthetic"}}}, {"cameras": ["a=synthetic:fps=10"]})
    assert [c.name for c in config.cameras] == ["a"]


@pytest.mark.parametrize("endpoint", ["tcp://[::1]:21400", "tcp://[::]:21400", "ipc:///tmp/" + "x" * 120])
def test_an_ipv6_endpoint_or_a_long_ipc_path_is_one_line(capsys, endpoint):
    code, err = one_line(capsys, ["run", "--endpoint", endpoint])
    assert code == exitcodes.USAGE
    assert ("IPv6" in err) if "[" in endpoint else ("the kernel takes at most 107" in err)
    with pytest.raises(BadEndpoint):
        Client(endpoint.replace("[::]", "[::1]"))


def test_a_config_file_that_is_not_utf8_is_one_line(capsys, tmp_path):
    (tmp_path / "c.toml").write_bytes(b"\xff\xfen\x00a\x00m\x00e\x00")
    code, err = one_line(capsys, ["run", "--config", str(tmp_path / "c.toml")])
    assert code == exitcodes.USAGE and "not UTF-8" in err


def test_a_snapshot_window_the_rings_cannot_hold_is_refused_at_once(service, capsys, tmp_path):
    code, err = one_line(capsys, ["snapshot", "--out", str(tmp_path / "s"), "--before", "1e9", "--after", "0"])
    assert code == exitcodes.USAGE and "at most 3600" in err
    argv = ["snapshot", "--endpoint", service.endpoint, "--out", str(tmp_path / "s"), "--before", "600"]
    code, err = one_line(capsys, argv)
    assert code == exitcodes.USAGE and "the rings hold at most" in err and "left" in err, err
    assert list(tmp_path.iterdir()) == []


def test_a_sync_report_of_too_many_tuples_is_refused_before_a_service_is_asked(capsys):
    code, err = one_line(capsys, ["sync-report", "--rate", "1e9", "--seconds", "1"])
    assert code == exitcodes.USAGE and "at most 1000" in err
    code, err = one_line(capsys, ["sync-report", "--endpoint", NOWHERE, "--rate", "1000", "--seconds", "600000"])
    assert code == exitcodes.USAGE and "tuples" in err  # not a time-out: nothing was asked


@pytest.mark.parametrize("command", ["record", "snapshot", "grab"])
def test_a_name_holding_a_line_break_is_still_one_line(service, capsys, tmp_path, command):
    """Found by the generator: a camera name with U+0085 (a line break to str.splitlines) made
    two lines of fxis record's refusal."""
    argv = [command, "--endpoint", service.endpoint, "--out", str(tmp_path / "o"), "--cameras", "0\x850"]
    code, err = one_line(capsys, [*argv, *(["--seconds", "0.2"] if command == "record" else [])])
    assert code == exitcodes.USAGE and "unknown camera" in err.lower() or "UNKNOWN_CAMERA" in err, err
