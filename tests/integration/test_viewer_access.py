"""Who may look (issue 21, item 4): a dashboard or Foxglove server on an address other hosts reach
requires a token, printed at start as a link (or read from a file), kept in a cookie after
the first visit; without it every request gets 401 and learns nothing, not even a camera's
name. Optional TLS from a certificate and key file. ``--insecure-bind`` still serves without.

"Other hosts reach" is decided from the address the service binds: ``0.0.0.0`` (every
interface) is reachable from other hosts, and the test connects to it through 127.0.0.1. The
tests run in a private network namespace (/work/isolated, CI's own machine), so no real
network sees these ports.
"""

from __future__ import annotations

import http.client
import json
import os
import re
import shlex
import signal
import socket
import ssl
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from websockets.exceptions import InvalidStatus

from fxis_shm.service.launch import ServiceProcess, free_tcp_port
from fxis_shm.shm import procstat

from ..conftest import assert_nothing_left, fxis_run_alone, wait_until
from .browser import Browser
from .conftest import SMALL
from .test_dashboard_browser import browser, picture, tiles  # noqa: F401  (browser: the fixture)
from .test_foxglove import SUBPROTOCOLS, FoxgloveClient

pytestmark = pytest.mark.integration

# names a leak would show: the cameras', the service's
CAMERAS = ["--camera", f"portcam=synthetic:fps=20,{SMALL}", "--camera", f"aftcam=synthetic:fps=20,{SMALL}"]
NAMES = ("portcam", "aftcam")
LINK = re.compile(r"^\s+(https?|wss?)://(\S+?):(\d+)/\?token=(<[^>]*>|\S+)$", re.M)
PATHS = [
    "/",
    "/status.json",
    "/dashboard.json",
    "/cameras/portcam/latest.jpg",
    "/cameras/portcam/stream.mjpg",
    "/cameras/nosuchcam/latest.jpg",
    "/tuple.zip",
    "/no/such/path",
]


@dataclass
class Served:
    svc: ServiceProcess
    http: int  # the dashboard's port
    foxglove: int  # the Foxglove server's port
    banner: str  # what fxis run printed at start
    token: str | None  # the token of the printed links (None: none printed)


def printing_to(path: Path) -> list[str]:
    """A wrapper for ServiceProcess that keeps what ``fxis run`` prints (it execs the service)."""
    return ["sh", "-c", f'exec "$@" > {shlex.quote(str(path))}', "sh"]


def serve(start, folder: Path, *args: str, http: str, foxglove: str, **kwargs) -> Served:
    """A service from ``start(*args, **kwargs)`` (a ServiceProcess), once its banner is printed
    (after every viewer is ready): its ports, banner and printed token."""
    out = folder / f"stdout-{free_tcp_port()}.txt"
    svc = start(*CAMERAS, *args, "--foxglove", foxglove, http=http, wrapper=printing_to(out), **kwargs)
    printed = lambda: out.read_text() if out.exists() else ""  # noqa: E731
    try:
        banner = wait_until(
            lambda: (lambda text: "Ctrl-C stops" in text and text)(printed()), timeout=30, what="the start-up banner"
        )
    except AssertionError as exc:  # what it printed and logged says where its start stood
        raise AssertionError(f"{exc}; it printed:\n{printed()}{svc.said()}") from None
    tokens = {match[3] for match in LINK.findall(banner)}
    assert len(tokens) <= 1, f"the viewers were given different tokens: {banner}"
    port = lambda address: int(address.rsplit(":", 1)[1])  # noqa: E731
    return Served(svc, port(http), port(foxglove), banner, tokens.pop() if tokens else None)


@pytest.fixture(scope="module")
def exposed(tmp_path_factory):
    """A service whose dashboard and Foxglove server listen on every interface: both require the
    random token printed at start."""
    folder = tmp_path_factory.mktemp("exposed")
    started = []

    def start(*args, **kwargs):
        svc = ServiceProcess(list(args), stderr=open(folder / "service.log", "w"), **kwargs)
        started.append(svc)
        return svc.start()

    try:
        yield serve(start, folder, http=f"0.0.0.0:{free_tcp_port()}", foxglove=f"0.0.0.0:{free_tcp_port()}")
    finally:
        for svc in started:
            svc.stop()
            assert_nothing_left(svc.name)


def fetch(port: int, path: str, headers: dict | None = None, tls: ssl.SSLContext | None = None):
    """(status, headers as a list of pairs, body) of one GET, no redirect followed."""
    if tls is None:
        connection = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    else:
        connection = http.client.HTTPSConnection("127.0.0.1", port, timeout=10, context=tls)
    try:
        connection.request("GET", path, headers=headers or {})
        answer = connection.getresponse()
        # a stream let in would never end: its first bytes show what it is
        body = answer.read(4096) if "multipart" in (answer.getheader("Content-Type") or "") else answer.read()
        return answer.status, answer.getheaders(), body
    finally:
        connection.close()


def header(headers: list[tuple[str, str]], name: str) -> list[str]:
    return [value for key, value in headers if key.lower() == name.lower()]


def cookie(port: int, token: str) -> dict:
    return {"Cookie": f"fxis-token-{port}={token}"}


def assert_refused(status: int, headers, body: bytes, served: Served) -> None:
    """401, and nothing in it that names the service or what it serves."""
    assert status == 401, (status, body)
    shown = (body + repr(headers).encode()).lower()
    for name in (*NAMES, served.svc.name):
        assert name.encode() not in shown, f"a refused request learnt {name!r}: {body!r} {headers!r}"
    assert b"fxis" not in shown and header(headers, "Set-Cookie") == [], (body, headers)


# ---- the token: printed, required, where it may come from ----


def test_the_link_with_a_random_token_is_printed_at_start(exposed):
    links = LINK.findall(exposed.banner)
    assert {(scheme, int(port)) for scheme, _, port, _ in links} == {("http", exposed.http), ("ws", exposed.foxglove)}
    assert all(host == socket.gethostname() for _, host, _, _ in links), "every interface: the host's name"
    assert re.fullmatch(r"[A-Za-z0-9_-]{43}", exposed.token), exposed.token  # secrets.token_urlsafe(32)
    assert "WARNING" not in exposed.banner  # nothing is open to other hosts without a token
    assert "travel unencrypted" in exposed.banner  # no TLS: said so


@pytest.mark.parametrize("path", PATHS)
def test_without_the_token_every_path_is_401_and_names_nothing(exposed, path):
    assert_refused(*fetch(exposed.http, path), exposed)


@pytest.mark.parametrize(
    "how",
    ["query", "query-prefix", "query-longer", "query-empty", "bearer", "token-scheme", "cookie", "other-port-cookie"],
)
def test_a_wrong_token_is_401(exposed, how):
    token, port = exposed.token, exposed.http
    wrong = {
        "query": ("/status.json?token=" + "x" * 43, {}),
        "query-prefix": ("/status.json?token=" + token[:-1], {}),
        "query-longer": ("/status.json?token=" + token + "x", {}),
        "query-empty": ("/status.json?token=", {}),
        "bearer": ("/status.json", {"Authorization": "Bearer " + token[::-1]}),
        "token-scheme": ("/status.json", {"Authorization": "Basic " + token}),  # right token, unknown scheme
        "cookie": ("/status.json", cookie(port, token.swapcase())),
        "other-port-cookie": ("/status.json", cookie(port + 1, token)),  # another service's cookie
    }[how]
    assert_refused(*fetch(port, *wrong), exposed)


def test_the_token_in_the_url_goes_into_a_cookie_and_on_without_it(exposed):
    status, headers, _ = fetch(exposed.http, f"/?token={exposed.token}")
    assert status == 303 and header(headers, "Location") == ["/"]
    [set_cookie] = header(headers, "Set-Cookie")
    assert set_cookie.startswith(f"fxis-token-{exposed.http}={exposed.token};"), set_cookie
    attributes = {a.strip().split("=")[0].lower(): a for a in set_cookie.split(";")[1:]}
    assert {"httponly", "path", "samesite", "max-age"} <= set(attributes), set_cookie
    assert attributes["samesite"].strip() == "SameSite=Strict" and attributes["path"].strip() == "Path=/"
    assert "secure" not in attributes  # plain http: a Secure cookie would never come back

    # the rest of the address stays as it was
    status, headers, _ = fetch(exposed.http, f"/cameras/portcam/latest.jpg?width=32&token={exposed.token}")
    assert status == 303 and header(headers, "Location") == ["/cameras/portcam/latest.jpg?width=32"]


def test_the_cookie_alone_lets_in(exposed):
    status, _, body = fetch(exposed.http, "/status.json", cookie(exposed.http, exposed.token))
    assert status == 200 and set(json.loads(body)["cameras"]) == set(NAMES)
    status, headers, body = fetch(
        exposed.http, "/cameras/portcam/latest.jpg?width=32", cookie(exposed.http, exposed.token)
    )
    assert status == 200 and body[:2] == b"\xff\xd8" and header(headers, "X-Fxis-Frame")
    status, _, body = fetch(exposed.http, "/", cookie(exposed.http, exposed.token))
    assert status == 200 and b"Save tuple" in body


@pytest.mark.parametrize("scheme", ["Bearer", "token", "bearer"])
def test_the_token_in_a_header_lets_in(exposed, scheme):
    status, headers, body = fetch(exposed.http, "/status.json", {"Authorization": f"{scheme} {exposed.token}"})
    assert status == 200 and set(json.loads(body)["cameras"]) == set(NAMES)
    assert header(headers, "Set-Cookie") == []  # a script's header: nothing to remember


def test_a_link_followed_from_another_site_gets_a_page_that_goes_on_by_itself(exposed):
    """A link followed from another site gets a page that goes on by itself (a SameSite=Strict
    cookie does not come along a redirect that began on another site)."""
    status, headers, body = fetch(exposed.http, f"/?a=1&token={exposed.token}", {"Sec-Fetch-Site": "cross-site"})
    assert status == 200 and b'http-equiv="refresh" content="0; url=/?a=1"' in body, body
    assert header(headers, "Set-Cookie")[0].startswith(f"fxis-token-{exposed.http}={exposed.token};")


def test_a_restarted_dashboard_keeps_the_token(exposed):
    with exposed.svc.client() as client:
        processes = client.status()["supervisor"]["processes"]
        restarts = processes["dashboard"]["restarts"]
        os.kill(processes["dashboard"]["pid"], signal.SIGKILL)
        wait_until(
            lambda: client.status()["supervisor"]["processes"]["dashboard"]["restarts"] == restarts + 1,
            timeout=20,
            what="the dashboard restarted",
        )

    def answers(headers):
        try:
            return fetch(exposed.http, "/status.json", headers)[0]
        except OSError:  # not listening yet
            return None

    assert wait_until(lambda: answers(cookie(exposed.http, exposed.token)), timeout=20, what="the dashboard") == 200
    assert answers({}) == 401


def test_the_token_does_not_show_on_any_command_line(exposed):
    """ps shows every process's arguments to every user: the token travels in the environment."""
    children = procstat.children(exposed.svc.proc.pid)
    lines = [" ".join(procstat.cmdline(pid)) for pid in [exposed.svc.proc.pid, *(c.pid for c in children)]]
    assert sum("fxis_shm.workers.dashboard" in line or "fxis_shm.workers.foxglove" in line for line in lines) == 2
    assert not [line for line in lines if exposed.token in line]


# ---- the Foxglove server ----


def test_foxglove_without_the_token_is_refused_and_with_it_serves_pictures(exposed):
    base = f"ws://127.0.0.1:{exposed.foxglove}"
    for url, headers in (
        (base, {}),
        (f"{base}/?token=wrong{exposed.token}", {}),
        (base, cookie(exposed.foxglove, "x")),
    ):
        with pytest.raises(InvalidStatus) as refused:
            FoxgloveClient(url, additional_headers=headers)
        response = refused.value.response
        assert_refused(response.status_code, list(response.headers.raw_items()), response.body or b"", exposed)

    for url, headers in (
        (f"{base}/?token={exposed.token}", {}),  # the printed link, as the app connects with it
        (f"{base}?token={exposed.token}", {}),
        (base, {"Authorization": f"Bearer {exposed.token}"}),
    ):
        picture = a_picture(FoxgloveClient(url, additional_headers=headers))
        assert picture.frame_id in NAMES and (picture.width, picture.height) == (64, 48)


def a_picture(client: FoxgloveClient):
    """One camera picture through a connected client (closed afterwards), decoded."""
    try:
        assert client.ws.subprotocol == SUBPROTOCOLS[0]  # the SDK's choice, through the front
        topics = {f"/{name}/image" for name in NAMES}
        client.until(lambda _: topics <= set(client.channels), what="the cameras' channels")
        client.subscribe(topics)
        channel, _, payload = client.until(lambda m: isinstance(m, tuple) and m, what="a picture")
        return client.decode(channel, payload)
    finally:
        client.close()


# ---- a token file, TLS, --insecure-bind ----


def self_signed(folder: Path) -> tuple[Path, Path, ssl.SSLContext]:
    """A certificate for 127.0.0.1 and its key, made now, and a client context that trusts it."""
    cert, key = folder / "cert.pem", folder / "key.pem"
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj", "/CN=127.0.0.1"]
        + ["-addext", "subjectAltName=IP:127.0.0.1", "-keyout", str(key), "-out", str(cert)],
        check=True,
        capture_output=True,
    )
    return cert, key, ssl.create_default_context(cafile=str(cert))  # hostname checked too


def test_a_token_file_and_tls(start_service, tmp_path):
    cert, key, trust = self_signed(tmp_path)
    token = "file-token.0123456789~abcdef"
    (tmp_path / "token").write_text(token + "\n")
    served = serve(
        start_service,
        tmp_path,
        *("--viewer-token-file", str(tmp_path / "token"), "--viewer-tls-cert", str(cert), "--viewer-tls-key", str(key)),
        http=f"127.0.0.1:{free_tcp_port()}",  # loopback: the token file asks for a token anyway
        foxglove=f"127.0.0.1:{free_tcp_port()}",
    )
    # the links name the file, not its token (which stays out of logs)
    assert token not in served.banner and served.token == f"<the token in {tmp_path / 'token'}>"
    assert {m[0] for m in LINK.findall(served.banner)} == {"https", "wss"}

    assert_refused(*fetch(served.http, "/status.json", tls=trust), served)
    status, headers, _ = fetch(served.http, f"/status.json?token={token}", tls=trust)
    assert status == 303 and "Secure" in header(headers, "Set-Cookie")[0]
    status, _, body = fetch(served.http, "/status.json", cookie(served.http, token), tls=trust)
    assert status == 200 and set(json.loads(body)["cameras"]) == set(NAMES)
    with pytest.raises((http.client.HTTPException, ConnectionError)):  # plain http is not answered
        fetch(served.http, "/status.json", cookie(served.http, token))

    base = f"wss://127.0.0.1:{served.foxglove}"
    with pytest.raises(InvalidStatus) as refused:
        FoxgloveClient(base, ssl=trust)
    assert refused.value.response.status_code == 401
    assert a_picture(FoxgloveClient(f"{base}/?token={token}", ssl=trust)).frame_id in NAMES


def test_insecure_bind_serves_other_hosts_without_a_token_and_warns(start_service, tmp_path):
    served = serve(
        start_service,
        tmp_path,
        "--insecure-bind",
        http=f"0.0.0.0:{free_tcp_port()}",
        foxglove=f"0.0.0.0:{free_tcp_port()}",
    )
    assert served.token is None
    warning = next(line for line in served.banner.splitlines() if "WARNING" in line)
    assert f"http://0.0.0.0:{served.http}" in warning and f"ws://0.0.0.0:{served.foxglove}" in warning
    status, _, body = fetch(served.http, "/status.json")
    assert status == 200 and set(json.loads(body)["cameras"]) == set(NAMES)
    client = FoxgloveClient(f"ws://127.0.0.1:{served.foxglove}")
    client.close()


@pytest.mark.parametrize(
    "make, args, words",
    [
        (None, ["--viewer-token-file", "/nonexistent/token"], ["viewer_token_file /nonexistent/token"]),
        ("short", ["--viewer-token-file", "{token}"], ["viewer_token_file", "at least 16 characters"]),
        ("with space in it, long enough", ["--viewer-token-file", "{token}"], ["at least 16 characters"]),
        (None, ["--viewer-tls-cert", "{token}"], ["viewer_tls_cert and viewer_tls_key go together"]),
        ("not a certificate", ["--viewer-tls-cert", "{token}", "--viewer-tls-key", "{token}"], ["viewer_tls_cert"]),
    ],
)
def test_bad_viewer_access_settings_are_refused_naming_them(tmp_path, make, args, words):
    path = tmp_path / "token"
    if make:
        path.write_text(make)
    result = fxis_run_alone("--http", f"0.0.0.0:{free_tcp_port()}", *(a.format(token=path) for a in args))
    assert result.returncode == 2, result.stderr
    assert all(w in result.stderr for w in words), result.stderr


# ---- a browser session through the printed link ----

CONNECT_JS = """new Promise(done => {
  const ws = new WebSocket(%s, %s);
  ws.onmessage = m => { done({protocol: ws.protocol, op: JSON.parse(m.data).op}); ws.close(); };
  ws.onerror = () => done({refused: true});
})"""


def app_connects(page: Browser, url: str) -> dict:
    """What a WebSocket opened by the page, as the Foxglove app opens one, first gets."""
    result = page.send(
        "Runtime.evaluate",
        expression=CONNECT_JS % (json.dumps(url), json.dumps(SUBPROTOCOLS)),
        awaitPromise=True,
        returnByValue=True,
        timeout=20,
    )
    return result["result"]["value"]


def test_a_browser_opens_the_link_and_keeps_the_token_in_its_cookie(exposed, browser, tmp_path):  # noqa: F811
    base, link = f"http://127.0.0.1:{exposed.http}", f"http://127.0.0.1:{exposed.http}/?token={exposed.token}"

    def live_page(what: str) -> dict:
        """The page's camera tiles once every picture is loaded, and each picture then changes."""
        shown = wait_until(
            lambda: (
                lambda t: set(t) == set(NAMES) and all(x["loaded"] and x["state"] == "up" for x in t.values()) and t
            )(tiles(browser)),
            timeout=30,
            interval=0.2,
            what=f"every camera's picture on the page ({what})",
        )
        for name, tile in shown.items():
            first = picture(browser, tile)
            wait_until(
                lambda tile=tile, first=first: not np.array_equal(picture(browser, tile), first),
                timeout=20,
                interval=0.2,
                what=f"camera {name}'s picture to change ({what})",
            )
        return shown

    browser.open(link)
    live_page("the printed link")
    assert browser.evaluate("location.href") == base + "/", "the token left in the address bar"
    assert exposed.token not in browser.evaluate("document.cookie")  # HttpOnly: no script reads it
    (tmp_path / "viewer-access-live.png").write_bytes(browser.screenshot())

    browser.open(base + "/")  # later visits: the cookie alone
    browser.evaluate("location.reload()")
    live_page("a visit without the token")

    # the Foxglove app connects with the browser's WebSocket, the printed URL as it is
    assert app_connects(browser, f"ws://127.0.0.1:{exposed.foxglove}/?token={exposed.token}") == {
        "protocol": SUBPROTOCOLS[0],
        "op": "serverInfo",
    }
    assert app_connects(browser, f"ws://127.0.0.1:{exposed.foxglove}/") == {"refused": True}

    # without the cookie the same address is refused, and the page shows nothing of the service
    browser.send("Network.clearBrowserCookies")
    browser.open(base + "/")
    text = wait_until(
        lambda: (lambda t: "401" in t and t)(browser.evaluate("document.body ? document.body.innerText : ''")),
        timeout=20,
        interval=0.2,
        what="the refusal shown",
    )
    assert not any(name in text for name in NAMES) and "fxis" not in text.lower(), text

    # the link followed from another site (here a data: page): the SameSite=Strict cookie is
    # stored and the page reached without a redirect that would drop it
    browser.open(f'data:text/html,<a id="go" href="{link}">cameras</a>')
    wait_until(lambda: browser.evaluate("!!document.getElementById('go')"), timeout=20, what="the other site's page")
    browser.evaluate("document.getElementById('go').click()")
    live_page("a link from another site")
    assert browser.evaluate("location.href") == base + "/"
