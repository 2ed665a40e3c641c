"""Who may look, without a service: which viewers require a token (fxis_shm.service.config), the
token's sources and checks (fxis_shm.viewers.access) on an app in this process, and what the
banner prints (fxis_shm.service.supervisor)."""

from __future__ import annotations

import asyncio
import re
import socket

import pytest
from aiohttp import web
from aiohttp.test_utils import TestClient, TestServer

from fxis_shm.errors import ConfigError
from fxis_shm.service.config import build_config, viewer_accesses
from fxis_shm.service.supervisor import link_host, viewer_lines
from fxis_shm.service.viewertokens import VIEWER_ACCESS_ENV, ViewerAccess, read_token_file
from fxis_shm.viewers.access import UNAUTHORIZED, cookie_name, header_token, middlewares, token_matches, without_token
from fxis_shm.viewers.wsfront import offered_protocols

TOKEN = "A" * 20 + "-_b" * 5
BOTH = {"foxglove": "127.0.0.1:8765"}  # with the default dashboard on 127.0.0.1:8080


# ---- which viewers require the token ----


@pytest.mark.parametrize(
    "flags, needing",
    [
        ({}, []),  # loopback: no token by default
        ({"http": "localhost:8080", "foxglove": "[::1]:8765"}, []),
        ({"http": "0.0.0.0:8080"}, ["http"]),  # every interface: other hosts reach it
        ({"http": "192.0.2.7:8080", "foxglove": "127.0.0.1:8765"}, ["http"]),  # one of two
        ({"http": "0.0.0.0:8080", "foxglove": "[::]:8765"}, ["http", "foxglove"]),
        ({"http": "eth0:8080"}, ["http"]),  # a name: assumed reachable
        ({"http": "0.0.0.0:8080", "insecure_bind": True}, []),  # said so: no token
        ({"http": "off", "foxglove": "0.0.0.0:8765"}, ["foxglove"]),
    ],
)
def test_a_token_is_required_where_other_hosts_reach_a_viewer(flags, needing):
    assert build_config({}, flags).token_viewers == needing


def test_a_token_file_asks_for_the_token_everywhere_even_with_insecure_bind(tmp_path):
    (tmp_path / "t").write_text(TOKEN)
    for extra in ({}, {"insecure_bind": True}):
        config = build_config({"viewer_token_file": str(tmp_path / "t")}, {**BOTH, **extra})
        assert config.token_viewers == ["http", "foxglove"]
        assert viewer_accesses(config) == {"http": ViewerAccess(TOKEN), "foxglove": ViewerAccess(TOKEN)}


def test_only_viewers_open_to_other_hosts_count_as_unauthenticated():
    assert build_config({}, {"http": "0.0.0.0:8080"}).exposed_unencrypted == []
    config = build_config({}, {"http": "0.0.0.0:8080", "pub": "tcp://0.0.0.0:7001", "insecure_bind": True})
    assert config.exposed_unencrypted == ["tcp://0.0.0.0:7001", "http://0.0.0.0:8080"]


def test_one_random_token_for_the_viewers_that_need_it():
    config = build_config({}, {"http": "0.0.0.0:8080", "foxglove": "127.0.0.1:8765"})
    access = viewer_accesses(config)
    assert re.fullmatch(r"[A-Za-z0-9_-]{43}", access["http"].token) and access["foxglove"].token is None
    assert viewer_accesses(config)["http"].token != access["http"].token  # new each start
    assert viewer_accesses(build_config({}, BOTH)) == {"http": ViewerAccess(), "foxglove": ViewerAccess()}


@pytest.mark.parametrize(
    "content", ["", "short-token", "has a space in it ok", "töken-with-umlaut-1234", "semi;colon;0123456789"]
)
def test_a_token_file_must_hold_a_long_url_safe_token(tmp_path, content):
    (tmp_path / "t").write_text(content)
    with pytest.raises(ConfigError, match="at least 16 characters"):
        read_token_file(str(tmp_path / "t"))
    with pytest.raises(ConfigError, match="viewer_token_file"):
        build_config({"viewer_token_file": str(tmp_path / "t")})


def test_a_token_file_is_read_without_surrounding_white_space(tmp_path):
    (tmp_path / "t").write_text(f"\n  {TOKEN}\n")
    assert read_token_file(str(tmp_path / "t")) == TOKEN
    with pytest.raises(ConfigError, match="viewer_token_file .*missing"):
        read_token_file(str(tmp_path / "missing"))


@pytest.mark.parametrize(
    "values, named",
    [
        ({"viewer_tls_cert": "c.pem"}, "go together"),
        ({"viewer_tls_key": "k.pem"}, "go together"),
        ({"viewer_tls_cert": "/no/c.pem", "viewer_tls_key": "/no/k.pem"}, "viewer_tls_cert /no/c.pem"),
        ({"viewer_token_file": 5}, "viewer_token_file must be the path"),
    ],
)
def test_bad_tls_or_token_settings_name_themselves(values, named):
    with pytest.raises(ConfigError, match=named):
        build_config(values)


def test_the_access_travels_in_the_environment_and_hides_the_token():
    access = ViewerAccess(TOKEN, "c.pem", "k.pem")
    assert ViewerAccess.from_environment(access.environment()) == access
    assert TOKEN not in repr(access)
    for environ in ({}, {VIEWER_ACCESS_ENV: "nonsense"}, {VIEWER_ACCESS_ENV: '{"other": 1}'}):
        with pytest.raises(ConfigError, match=VIEWER_ACCESS_ENV):
            ViewerAccess.from_environment(environ)


# ---- the banner ----


def test_the_banner_prints_the_link_with_a_made_token_and_only_names_a_token_file(tmp_path):
    config = build_config({}, {"http": "0.0.0.0:8080", "foxglove": "127.0.0.1:8765"})
    lines = viewer_lines(config, {"http": ViewerAccess(TOKEN), "foxglove": ViewerAccess()})
    assert f"      http://{socket.gethostname()}:8080/?token={TOKEN}" in lines
    assert "  Foxglove WebSocket server on ws://127.0.0.1:8765 (10 pictures/s per camera)" in lines
    assert any("travel unencrypted" in line for line in lines)

    (tmp_path / "t").write_text(TOKEN)
    config = build_config({"viewer_token_file": str(tmp_path / "t")}, {"http": "127.0.0.1:8080"})
    lines = viewer_lines(config, viewer_accesses(config))
    assert lines[1] == f"      http://127.0.0.1:8080/?token=<the token in {tmp_path / 't'}>"
    assert not any(TOKEN in line or "unencrypted" in line for line in lines)  # loopback: no note


@pytest.mark.parametrize(
    "address, shown",
    [("127.0.0.1:80", "127.0.0.1:80"), ("[::1]:80", "[::1]:80"), ("[::]:80", f"{socket.gethostname()}:80")],
)
def test_a_link_names_this_host_for_every_interface(address, shown):
    assert link_host(address, "http") == shown


# ---- the token's checks ----


def test_tokens_match_only_whole():
    assert token_matches(TOKEN, TOKEN)
    for other in (None, "", TOKEN[:-1], TOKEN + "x", TOKEN.lower(), "ü" * 5):
        assert not token_matches(other, TOKEN), other


@pytest.mark.parametrize(
    "value, token",
    [
        ("Bearer abc", "abc"),
        ("token abc", "abc"),
        ("bearer   abc  ", "abc"),
        ("Basic abc", None),
        ("Bearer", None),
        ("", None),
        (None, None),
        ("abc", None),
    ],
)
def test_the_header_token(value, token):
    assert header_token(value) == token


@pytest.mark.parametrize(
    "path, query, target",
    [
        ("/", [("token", "x")], "/"),
        ("/cameras/a/latest.jpg", [("width", "32"), ("token", "x")], "/cameras/a/latest.jpg?width=32"),
        ("/a", [("token", "x"), ("b", "1"), ("token", "y"), ("b", "2")], "/a?b=1&b=2"),
        ("//evil.example/x", [("token", "x")], "/evil.example/x"),  # never another host
        ("/s", [("q", "a b&c")], "/s?q=a+b%26c"),
    ],
)
def test_the_address_to_go_on_to_drops_only_the_token(path, query, target):
    assert without_token(path, query) == target


def test_cookies_are_per_port_and_subprotocols_are_read_in_order():
    assert cookie_name(8080) != cookie_name(8081)
    assert offered_protocols("foxglove.sdk.v1, foxglove.websocket.v1") == ["foxglove.sdk.v1", "foxglove.websocket.v1"]
    assert offered_protocols(None) == [] and offered_protocols(" , ") == []


def test_no_token_no_check():
    assert middlewares(ViewerAccess(), 80) == [] and len(middlewares(ViewerAccess(TOKEN), 80)) == 1


def test_the_middleware_on_an_app():
    """Every path (an unknown one too) is 401 without the token; with it, the handler answers."""

    async def secret(request):
        return web.Response(text="secret camera names")

    async def scenario():
        app = web.Application(middlewares=middlewares(ViewerAccess(TOKEN), 8080))
        app.router.add_get("/x", secret)
        async with TestClient(TestServer(app)) as client:
            for path in ("/x", "/nowhere", f"/x?token={TOKEN}x"):
                answer = await client.get(path, allow_redirects=False)
                assert (answer.status, await answer.text()) == (401, UNAUTHORIZED), path
            answer = await client.get(f"/x?token={TOKEN}", allow_redirects=False)
            assert answer.status == 303 and answer.headers["Location"] == "/x"
            answer = await client.get("/x")  # the client keeps the cookie
            assert (answer.status, await answer.text()) == (200, "secret camera names")
            answer = await client.post(f"/x?token={TOKEN}")  # not a visit: no redirect (405: GET only)
            assert answer.status == 405

    asyncio.run(scenario())
