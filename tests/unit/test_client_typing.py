"""``copy=False`` is typed apart from copied frames (issue 46 item 4): the type checker knows a
view's ``still_valid()`` from the overloads of the client's requests, as pyzmq's
``recv_multipart(copy=False)`` answers Frames where the default answers bytes."""

from __future__ import annotations

import textwrap
from pathlib import Path

from mypy import api

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
    out, err, status = api.run(
        ["--strict", "--python-version", "3.11", "--follow-imports", "silent", "--no-incremental", str(source)]
    )
    lines = [line for line in out.splitlines() if "error:" in line]
    # the one error is the one the snippet plants: every assert_type held
    assert len(lines) == 1 and '"Frame" has no attribute "nonexistent"' in lines[0], out + err
    assert status == 1
