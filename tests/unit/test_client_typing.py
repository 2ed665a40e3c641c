"""``copy=False`` is typed apart from copied frames (issue 46 item 4): the type checker knows a
view's ``still_valid()`` from the overloads of the client's requests, as pyzmq's
``recv_multipart(copy=False)`` answers Frames where the default answers bytes."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

SNIPPET = textwrap.dedent(
    """
    from typing import assert_type

    from fxis_shm import Client
    from fxis_shm.client.frames import Frame, FrameTuple, FrameView

    def typed(c: Client, copy: bool) -> None:
        assert_type(c.image("cam0"), Frame)
        assert_type(c.image("cam0", copy=False), FrameView)
        assert_type(c.tuple(), FrameTuple[Frame])
        assert_type(c.tuple(copy=False), FrameTuple[FrameView])
        assert_type(c.tuple(copy=False)["cam0"], FrameView)
        assert_type(c.latest(copy=False), FrameTuple[FrameView])
        assert_type(c.sequence("consecutive", camera="cam0", count=3), list[Frame])
        assert_type(c.sequence("consecutive", camera="cam0", copy=False), list[FrameView])
        assert_type(c.sequence("consecutive", count=3, copy=False), list[FrameTuple[FrameView]])
        assert_type(c.tuple(copy=copy), FrameTuple[Frame])  # a copy not known: a Frame at least
        assert_type(c.tuple(copy=False).still_valid(), bool)
        c.tuple()["cam0"].nonexistent  # the checker knows a Frame's attributes
    """
)


def test_copy_false_answers_views_and_the_default_copies(tmp_path: Path) -> None:
    source = tmp_path / "uses_the_client.py"
    source.write_text(SNIPPET)
    # a process of its own: mypy run in this one would raise its recursion limit for the tests after
    flags = ["--strict", "--python-version", "3.11", "--follow-imports", "silent", "--no-incremental"]
    run = subprocess.run(
        [sys.executable, "-m", "mypy", *flags, str(source)], capture_output=True, text=True, timeout=300
    )
    lines = [line for line in run.stdout.splitlines() if "error:" in line]
    # the one error is the one the snippet plants: every assert_type held
    assert len(lines) == 1 and '"Frame" has no attribute "nonexistent"' in lines[0], run.stdout + run.stderr
    assert run.returncode == 1
