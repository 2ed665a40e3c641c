"""Who may change a camera through the dashboard (issue 42, finding 1), tried as an attacker
would: curl with the bodies a form or another site's page can send, a foreign Origin, a foreign
Host (DNS rebinding), and a second local user made for the test. Each is refused and the
camera's setting stays as it was; the operator with the operator token changes it."""

from __future__ import annotations

import json
import pwd
import subprocess

import pytest

from fxis_shm import Client
from fxis_shm.service.launch import free_tcp_port

from ..conftest import fxis
from .conftest import SMALL, client_keys
from .neighbour import as_user, local_user
from .test_dashboard import service_ok
from .test_dashboard_browser import browser  # noqa: F401  (the fixture, by name)
from .test_dashboard_tuning import CONTROL_JS, SET_JS

pytestmark = pytest.mark.integration

DISABLED_JS = """(() => {
  const tile = document.querySelector('.camera[data-camera="a"]');
  const number = tile && tile.querySelector('input[type=number][data-key="exposure_us"]');
  return number ? {disabled: number.disabled, said: tile.querySelector('.said').textContent} : null;
})()"""
OPERATOR_TOKEN = "operator-token-0123456789abcdef"
BODY = json.dumps({"exposure_us": 1234})


def curl(url: str, *options: str, user: pwd.struct_passwd | None = None) -> tuple[int, str]:
    """(status, body) of a request made by the curl program, as ``user`` where given."""
    command = ["curl", "-s", "-o", "-", "-w", "\n%{http_code}", "--max-time", "20", *options, url]
    if user is not None:  # that user's own process: no root, no file of ours it could read
        command = as_user(user, command)
    done = subprocess.run(command, capture_output=True, text=True, timeout=30)
    body, _, status = done.stdout.rpartition("\n")
    return int(status), body


def post(url: str, *options: str, body: str = BODY, user=None) -> tuple[int, str]:
    return curl(url, "-X", "POST", "--data", body, *options, user=user)


def start_operated(start_service, wait, keys, tmp_path, *options: str):
    """A service under --curve-operators (one key, ``operator``) with its dashboard and
    ``options``: (svc, the dashboard's base URL)."""
    folder, allowed = keys
    assert fxis("keys", "--out", str(folder), "--name", "operator").returncode == 0
    operators = tmp_path / "operators"
    operators.mkdir()
    (operators / "operator.key").write_bytes((folder / "operator.key").read_bytes())
    port = free_tcp_port()
    curve = ["--curve-secret", str(folder / "server.key_secret"), "--curve-clients", str(allowed)]
    svc = start_service(
        "--camera",
        f"a=synthetic:fps=20,{SMALL}",
        *curve,
        "--curve-operators",
        str(operators),
        *options,
        client_keys=client_keys(folder, "alice"),
        http=f"127.0.0.1:{port}",
    )
    base = f"http://127.0.0.1:{port}"
    wait(lambda: service_ok(base), timeout=30, what="the dashboard through CurveZMQ")
    return svc, base


@pytest.fixture
def operated(start_service, wait, keys, tmp_path):
    """A service under --curve-operators whose dashboard has an operator token: (svc, base, log,
    a client with an operator's key)."""
    token_file = tmp_path / "operator.token"
    token_file.write_text(OPERATOR_TOKEN)
    token_file.chmod(0o600)
    svc, base = start_operated(start_service, wait, keys, tmp_path, "--operator-token-file", str(token_file))
    with Client(svc.endpoint, timeout=15, keys=client_keys(keys[0], "operator")) as operator:
        yield svc, base, tmp_path / "service0.log", operator


def exposure(client) -> float:
    return client.settings("a")["values"]["exposure_us"]


def test_cross_site_and_foreign_host_requests_change_nothing(operated):
    svc, base, log, operator = operated
    url = base + "/cameras/a/settings.json"
    before = exposure(operator)
    assert before != 1234
    token = ["-H", f"X-Fxis-Operator-Token: {OPERATOR_TOKEN}"]
    json_type = ["-H", "Content-Type: application/json"]
    for options, status, words in [
        (["-H", "Content-Type: text/plain", "-H", "Origin: http://evil.example", *token], 403, "another site"),
        (["-H", "Content-Type: text/plain", *token], 415, "application/json"),
        (["-H", "Content-Type: application/x-www-form-urlencoded", *token], 415, "application/json"),
        ([*json_type, "-H", "Origin: http://evil.example", *token], 403, "another site"),
        ([*json_type, "-H", "Origin: null", *token], 403, "another site"),
        ([*json_type, "-H", "Host: attacker.example:80", *token], 403, "not an address this dashboard serves"),
        ([*json_type, "-H", "X-Fxis-Operator-Token: not-the-token"], 403, "operator token"),
        (json_type, 403, "operator token"),
    ]:
        answer = post(url, *options)
        assert answer[0] == status and words in answer[1], (options, answer)
    for path in ("/status.json", "/dashboard.json", "/cameras/a/settings.json", "/"):  # reads: DNS rebinding
        answer = curl(base + path, "-H", "Host: attacker.example")
        assert answer[0] == 403 and "not an address" in answer[1], (path, answer)
    assert exposure(operator) == before
    refusals = [line for line in log.read_text().splitlines() if "refused a request from 127.0.0.1" in line]
    assert 0 < len(refusals) <= 5, refusals  # one line per kind in the period, not one per request

    status, body = post(url, *json_type, *token, "-H", f"Origin: {base}")  # the page's own request
    assert status == 200 and json.loads(body)["changed"] == {"exposure_us": 1234.0}, body
    assert exposure(operator) == 1234
    assert curl(base + "/status.json", "-H", f"Host: localhost:{base.rsplit(':', 1)[1]}")[0] == 200
    answer = json.loads(curl(url)[1])
    assert answer["dashboard"]["mode"] == "operator token" and answer["values"]["exposure_us"] == 1234


def test_a_second_local_user_cannot_change_a_camera(operated, tmp_path):
    svc, base, _, operator = operated
    url = base + "/cameras/a/settings.json"
    before = exposure(operator)
    with local_user() as neighbour:
        assert curl(base + "/status.json", user=neighbour)[0] == 200  # loopback, no viewer token: it may look
        for options in ([], ["-H", "Content-Type: application/json"]):
            status, body = post(url, *options, user=neighbour)
            assert status in (403, 415), (options, status, body)
        token_file = tmp_path / "operator.token"  # nor read the operator token
        done = subprocess.run(as_user(neighbour, ["cat", str(token_file)]), capture_output=True, text=True)
        assert done.returncode != 0 and OPERATOR_TOKEN not in done.stdout
    assert exposure(operator) == before


def test_under_operators_without_an_operator_token_the_dashboard_only_shows(
    browser,  # noqa: F811
    start_service,
    wait,
    keys,
    tmp_path,
):
    _, base = start_operated(start_service, wait, keys, tmp_path)
    url = base + "/cameras/a/settings.json"
    status, body = post(url, "-H", "Content-Type: application/json", "-H", f"Origin: {base}")
    assert status == 403 and "only shows settings" in body and "--operator-token-file" in body
    answer = json.loads(curl(url)[1])
    assert answer["dashboard"]["mode"] == "read only" and answer["values"]["exposure_us"] != 1234
    browser.open(base + "/")  # the page greys its controls out and says why
    control = wait(lambda: browser.evaluate(DISABLED_JS), timeout=30, what="the controls of camera a")
    assert control == {"disabled": True, "said": answer["dashboard"]["why"]}


def test_the_page_changes_a_camera_with_the_operator_token_and_not_without(browser, operated, wait):  # noqa: F811
    """In Chromium: the page opened from the #operator= link sends the token with its JSON
    changes (same origin); opened without it, the change is refused on the card."""
    _, base, _, operator = operated
    browser.open(base + "/")
    wait(lambda: browser.evaluate(CONTROL_JS % ("exposure_us", "exposure_us")), timeout=30, what="the controls")
    assert browser.evaluate("document.getElementById('operator').hidden") is False  # it asks for the token
    browser.evaluate(SET_JS % ("exposure_us", 3000))
    refused = wait(
        lambda: (c := browser.evaluate(CONTROL_JS % ("exposure_us", "exposure_us")))["state"] == "refused" and c,
        timeout=20,
        what="the refusal on the card",
    )
    assert "operator token" in refused["said"] and exposure(operator) != 3000

    browser.open(f"{base}/#operator={OPERATOR_TOKEN}")
    wait(lambda: browser.evaluate(CONTROL_JS % ("exposure_us", "exposure_us")), timeout=30, what="the controls")
    assert "operator" not in browser.evaluate("location.href")  # out of the address bar and the history
    browser.evaluate(SET_JS % ("exposure_us", 3000))
    wait(
        lambda: browser.evaluate(CONTROL_JS % ("exposure_us", "exposure_us"))["said"] == "exposure_us = 3000",
        timeout=20,
        what="the camera's answer on the card",
    )
    assert exposure(operator) == 3000
