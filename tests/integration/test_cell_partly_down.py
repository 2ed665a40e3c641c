"""``fxis dashboard A B`` for a cell that is partly down (issue 33, findings 5-7): it starts
with only A answering, learns B's cameras when B comes, and while B is gone saves partial
tuples (A's cameras plus B's as ``missing``) and shows B's clock as unknown. Real services,
a real ``fxis dashboard`` process, real HTTP."""

from __future__ import annotations

import io
import json
import zipfile

import pytest

from fxis_shm.service.launch import free_tcp_port

from ..conftest import wait_until
from .conftest import SMALL
from .test_cell_dashboard import cell_dashboard
from .test_dashboard import get, view

pytestmark = pytest.mark.integration


@pytest.fixture
def half_cell(start_service, tmp_path):
    """Service A up, B's endpoint with nothing behind it yet, and ``fxis dashboard A B``."""
    a = start_service("--camera", f"left=synthetic:fps=20,{SMALL}")
    b_endpoint = f"tcp://127.0.0.1:{free_tcp_port()}"
    with cell_dashboard([a.endpoint, b_endpoint], tmp_path / "dashboard.out") as base:
        yield base, a, b_endpoint


def services(base: str) -> dict:
    try:
        return view(base).get("services") or {}
    except OSError:  # not listening yet
        return {}


def answering(base: str, wanted: dict[str, bool]):
    """The view once each service's ``ok`` is as ``wanted`` says (endpoint -> answers)."""
    now = services(base)
    return now if {e: now.get(e, {}).get("ok") for e in wanted} == wanted else None


def saved_tuple(base: str) -> tuple[set[str], dict]:
    status, _, body = get(base + "/tuple.zip")
    assert status == 200, body
    with zipfile.ZipFile(io.BytesIO(body)) as archive:
        return set(archive.namelist()), json.loads(archive.read("tuple.json"))


def test_a_cell_dashboard_starts_without_b_learns_b_when_it_comes_and_keeps_saving_when_it_goes(
    half_cell, start_service
):
    base, a, b_endpoint = half_cell
    shown = wait_until(lambda: answering(base, {a.endpoint: True, b_endpoint: False}), timeout=30, what="A alone")
    assert shown[b_endpoint]["clock"] is None and shown[a.endpoint]["clock"]["method"] == "same clock"
    assert set(view(base)["configured"]) == {"left"}
    names, described = saved_tuple(base)
    assert names == {"left.png", "tuple.json"} and set(described["frames"]) == {"left"}

    b = start_service("--camera", f"right=synthetic:fps=20,phase_ms=9,{SMALL}", endpoint=b_endpoint)
    wait_until(lambda: answering(base, {a.endpoint: True, b_endpoint: True}), timeout=30, what="B come")
    wait_until(lambda: set(view(base)["configured"]) == {"left", "right"}, timeout=10, what="B's camera learnt")
    assert get(base + "/cameras/right/latest.jpg")[0] == 200
    names, described = wait_until(lambda: (t := saved_tuple(base))[1]["frames"].keys() == {"left", "right"} and t)
    assert names == {"left.png", "right.png", "tuple.json"} and described["missing"] == []

    b.stop()
    shown = wait_until(lambda: answering(base, {a.endpoint: True, b_endpoint: False}), timeout=30, what="B gone")
    assert shown[b_endpoint]["clock"] is None  # not "0 ms (same clock)": a gone service's clock is not known
    names, described = saved_tuple(base)
    assert names == {"left.png", "tuple.json"} and described["missing"] == ["right"]
    status, _, body = get(base + "/cameras/right/latest.jpg")
    assert status == 503 and f"its service {b_endpoint} does not answer" in body.decode()
