"""Who may change a camera, without a service (issue 42): the dashboard's Host, Origin and
operator-token rules (fxis_shm.viewers.guard), who may change on each face and what the banner
says of it (fxis_shm.service.changers), and the ROS 2 bridge's refusal when it only reads."""

from __future__ import annotations

import json

import pytest

from fxis_shm.errors import ConfigError
from fxis_shm.ros2.follow import Counts
from fxis_shm.ros2.settings import READ_ONLY, SettingsRequests
from fxis_shm.service.changers import change_lines, dashboard_access, ros2_may_change
from fxis_shm.service.config import ServiceConfig, build_config
from fxis_shm.service.ros2config import Ros2Settings
from fxis_shm.service.viewertokens import ViewerAccess
from fxis_shm.viewers.guard import RefusalLog, changes, host_allowed, same_origin

NAMES = {"localhost", "cellpc", "cellpc.lab"}


@pytest.mark.parametrize(
    "host, bound, allowed",
    [
        ("127.0.0.1:8080", "127.0.0.1", True),
        ("localhost:8080", "127.0.0.1", True),
        ("[::1]:8080", "127.0.0.1", True),
        ("LOCALHOST.:8080", "127.0.0.1", True),
        ("attacker.example:8080", "127.0.0.1", False),  # DNS rebinding: the page's own name
        ("127.0.0.1:8081", "127.0.0.1", False),  # another port
        ("127.0.0.1", "127.0.0.1", False),  # port 80
        ("cellpc:8080", "127.0.0.1", False),  # a loopback dashboard is no other host's
        ("192.0.2.7:8080", "0.0.0.0", True),  # every interface: an address
        ("cellpc.lab:8080", "0.0.0.0", True),  # or this host's name
        ("attacker.example:8080", "0.0.0.0", False),
        ("192.0.2.7:8080", "192.0.2.7", True),
        ("cellpc:8080", "192.0.2.7", True),
        ("192.0.2.8:8080", "192.0.2.7", False),
        ("", "127.0.0.1", False),
        (None, "127.0.0.1", False),
        ("127.0.0.1:http", "127.0.0.1", False),
        ("[::1:8080", "127.0.0.1", False),
    ],
)
def test_host_names_an_address_the_dashboard_serves(host, bound, allowed):
    assert host_allowed(host, bound, 8080, tls=False, names=NAMES) is allowed


def test_the_default_port_of_the_scheme_counts():
    assert host_allowed("localhost", "127.0.0.1", 443, tls=True, names=NAMES)
    assert not host_allowed("localhost", "127.0.0.1", 443, tls=False, names=NAMES)


@pytest.mark.parametrize(
    "origin, same",
    [
        ("http://127.0.0.1:8080", True),
        ("http://127.0.0.1:8080/", False),  # an Origin has no path: not one a browser sends
        ("https://127.0.0.1:8080", False),
        ("http://localhost:8080", False),  # another origin, though the same server
        ("http://evil.example", False),
        ("null", False),
        ("", False),
    ],
)
def test_an_origin_is_the_pages_own(origin, same):
    assert same_origin(origin, "127.0.0.1:8080", tls=False) is same


def test_refusals_are_logged_once_a_period_with_the_count_between(caplog):
    now = [0.0]
    refusals = RefusalLog(period=10.0, clock=lambda: now[0])
    logged = [refusals.refused("origin", "127.0.0.1", "another site") for _ in range(50)]
    assert logged == [True] + [False] * 49
    assert refusals.refused("host", "127.0.0.1", "a foreign Host")  # another kind: its own line
    now[0] = 10.5
    assert refusals.refused("origin", "127.0.0.1", "another site")
    assert "and 49 more like it" in caplog.records[-1].getMessage()


def _config(**values) -> ServiceConfig:
    return build_config({}, {"cameras": ["a=synthetic"], **values})


def test_under_operators_the_dashboard_changes_with_the_operator_token_or_not_at_all(tmp_path, monkeypatch):
    token = tmp_path / "operator.token"
    token.write_text("T" * 24)
    open_config = _config()
    operated = ServiceConfig(curve_operators="ops", operator_token_file=str(token))
    read_only = ServiceConfig(curve_operators="ops")
    assert changes(dashboard_access(open_config, ViewerAccess()))["mode"] == "open"
    access = dashboard_access(operated, ViewerAccess())
    assert access.operator_token == "T" * 24 and changes(access)["mode"] == "operator token"
    assert "T" * 24 not in repr(access) and "T" * 24 in access.environment()[next(iter(access.environment()))]
    assert changes(dashboard_access(read_only, ViewerAccess()))["mode"] == "read only"


def test_the_operator_token_is_not_the_viewer_token(tmp_path):
    viewer = tmp_path / "viewer.token"
    viewer.write_text("V" * 24)
    with pytest.raises(ConfigError, match="holds the viewer token"):
        _config(viewer_token_file=str(viewer), operator_token_file=str(viewer))
    with pytest.raises(ConfigError, match="operator_token_file .*at least 16"):
        (tmp_path / "short").write_text("short")
        _config(operator_token_file=str(tmp_path / "short"))


@pytest.mark.parametrize(
    "operators, setting, may",
    [(None, None, True), ("ops", None, False), ("ops", "allow", True), (None, "read", False)],
)
def test_ros2_reads_only_under_operators_unless_allowed(operators, setting, may):
    config = ServiceConfig(curve_operators=operators, ros2=Ros2Settings(settings=setting))
    assert ros2_may_change(config) is may


def test_the_banner_says_which_faces_change_settings(tmp_path):
    token = tmp_path / "operator.token"
    token.write_text("T" * 24)
    plain = "\n".join(change_lines(ServiceConfig(ros2=Ros2Settings())))
    assert "every client let in" in plain and "the dashboard (whoever may open it)" in plain
    assert "ROS 2 NS/settings (any node" in plain and "only be read" not in plain
    operated = "\n".join(change_lines(ServiceConfig(curve_operators="ops", ros2=Ros2Settings())))
    assert "operators' keys only" in operated
    assert "only be read over the dashboard (no --operator-token-file), ROS 2 NS/settings" in operated
    with_token = "\n".join(change_lines(ServiceConfig(curve_operators="ops", operator_token_file=str(token))))
    assert "the dashboard (with the operator token)" in with_token
    assert f"/#operator=<the token in {token}>" in with_token and "T" * 24 not in with_token


class _Client:
    def __init__(self):
        self.changed = []

    def settings(self, camera):
        return {"values": {"gain": 0.0}}

    def configure(self, camera, **values):
        self.changed.append(values)
        return {"changed": values}


def test_a_bridge_that_only_reads_answers_reads_and_refuses_changes():
    requests = SettingsRequests.__new__(SettingsRequests)  # the answers alone: no DDS participant
    requests.may_change, requests.counts = False, Counts()
    client = _Client()
    assert requests.answer(client, json.dumps({"id": 1, "camera": "a"}))["values"] == {"gain": 0.0}
    refused = requests.answer(client, json.dumps({"id": 2, "camera": "a", "set": {"gain": 6}}))
    assert refused == {"id": 2, "camera": "a", "error": READ_ONLY} and client.changed == []


def test_the_cell_dashboard_takes_an_operator_token_of_its_own(tmp_path):
    from argparse import Namespace

    from fxis_shm.cli.dashboard import access_for

    (tmp_path / "op").write_text("O" * 24)
    (tmp_path / "viewer").write_text("V" * 24)
    args = Namespace(
        http="127.0.0.1:8080",
        insecure_bind=False,
        viewer_token_file=str(tmp_path / "viewer"),
        viewer_tls_cert=None,
        viewer_tls_key=None,
        operator_token_file=str(tmp_path / "op"),
    )
    access = access_for(args)
    assert (access.token, access.operator_token, changes(access)["mode"]) == ("V" * 24, "O" * 24, "operator token")
    with pytest.raises(ConfigError, match="holds the viewer token"):
        access_for(Namespace(**{**vars(args), "operator_token_file": str(tmp_path / "viewer")}))
    assert changes(access_for(Namespace(**{**vars(args), "operator_token_file": None})))["mode"] == "open"


def test_the_foxglove_server_changes_no_camera_setting():
    """Its one parameter is its own picture rate: one named as a camera setting changes nothing."""
    from foxglove import Parameter

    from fxis_shm.viewers.foxglove_live import RATE_PARAMETER, RateParameter

    rate = RateParameter(10)
    answer = rate.on_set_parameters(None, [Parameter("exposure_us", value=1234.0), Parameter("a.gain", value=6.0)])
    assert [(p.name, p.get_value()) for p in answer] == [(RATE_PARAMETER, 10.0)]
    assert [p.name for p in rate.on_get_parameters(None, [])] == [RATE_PARAMETER]
