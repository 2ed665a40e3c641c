"""The reference docs come from the code, and the README stays a five-minute read (issue 45)."""

from __future__ import annotations

import inspect
import pathlib
import re
import subprocess
import sys

from fxis_shm.client.api import ClientApi

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_the_cli_reference_is_what_help_prints():
    checked = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "cli_reference.py"), "--check"], capture_output=True, text=True
    )
    assert checked.returncode == 0, checked.stderr


def test_the_readme_is_at_most_150_lines():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 150


def test_every_page_of_docs_is_on_the_site():
    site = (ROOT / "mkdocs.yml").read_text()
    pages = {str(p.relative_to(ROOT / "docs")) for p in (ROOT / "docs").rglob("*.md")}
    assert {p for p in pages if not re.search(rf":\s*{re.escape(p)}\s*$", site, re.MULTILINE)} == set()


def test_the_requests_say_what_they_take_return_and_raise():
    for name in ("image", "tuple", "latest", "sequence", "snapshot"):
        doc = inspect.getdoc(getattr(ClientApi, name)) or ""
        for section in ("Parameters\n----------", "Returns\n-------", "Raises\n------"):
            assert section in doc, f"ClientApi.{name} lacks {section.splitlines()[0]}"
        documented = re.findall(r"^(\w+(?:, \w+)*)$", doc.split("Returns")[0], re.MULTILINE)
        named = {n for line in documented for n in line.split(", ")}
        parameters = set(inspect.signature(getattr(ClientApi, name)).parameters) - {"self"}
        assert parameters - named == set(), f"ClientApi.{name} does not document {parameters - named}"


def test_the_calls_about_the_services_say_what_they_return_and_raise():
    for name in ("subscribe", "frame_times", "events", "status", "time", "clock_estimate"):
        doc = inspect.getdoc(getattr(ClientApi, name)) or ""
        for section in ("Returns\n-------", "Raises\n------"):
            assert section in doc, f"ClientApi.{name} lacks {section.splitlines()[0]}"
    for name in ("subscribe", "frame_times"):  # the ones that take parameters name each
        doc = inspect.getdoc(getattr(ClientApi, name)) or ""
        parameters = set(inspect.signature(getattr(ClientApi, name)).parameters) - {"self"}
        assert all(f"\n{p}\n" in doc.split("Returns")[0] for p in parameters), name


def test_the_settings_calls_and_the_frames_say_what_they_are():
    from fxis_shm.client.frames import Frame, FrameTuple
    from fxis_shm.client.single import SingleClient

    for call in (SingleClient.settings, SingleClient.configure):
        doc = inspect.getdoc(call) or ""
        assert all(s in doc for s in ("Parameters\n----------", "Returns\n-------", "Raises\n------")), call
    for kind in (Frame, FrameTuple):
        assert "Attributes\n----------" in (inspect.getdoc(kind) or ""), kind
