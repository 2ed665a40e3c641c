"""The options of a frame request as one value (fxis_shm.client.requestoptions), and the
deprecated spellings of the client's public calls: each still works and warns, pointing at the
caller's line."""

from __future__ import annotations

import warnings

import pytest

from fxis_shm.client import arguments
from fxis_shm.client.requestoptions import RequestOptions
from fxis_shm.errors import InvalidArgument
from fxis_shm.formats.videotracks import VideoSettings


def test_timeout_in_seconds_is_the_wire_timeout_in_ms_and_takes_the_compiled_read_off():
    options = RequestOptions.given(0.25, True, None, None)
    assert options.timeout_ms == 250 and not options.plain
    assert RequestOptions.given(None, False, None, None).plain
    assert not RequestOptions(None, True, "jpeg", None).plain and not RequestOptions(None, True, None, 80).plain


def test_timeout_ms_still_works_and_warns_at_the_callers_line():
    def operation(**given: float) -> RequestOptions:  # as a client's public call makes it
        return RequestOptions.given(given.get("timeout"), True, None, None, given.get("timeout_ms"))

    with pytest.warns(DeprecationWarning, match="timeout_ms= is deprecated: give timeout= in seconds") as caught:
        options = operation(timeout_ms=400)
    assert options.timeout == 0.4 and caught[0].filename == __file__
    with pytest.warns(DeprecationWarning):
        assert operation(timeout=0.1, timeout_ms=400).timeout == 0.1  # timeout wins
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert operation(timeout=0.1).timeout == 0.1  # no warning without timeout_ms


def keywords(**given: object) -> dict[str, object]:
    return {"codec": None, "encoder": None, "crf": None, "preset": None, "gop_s": None, **given}


def test_the_old_video_keywords_make_the_same_settings_and_warn():
    with pytest.warns(DeprecationWarning, match=r"snapshot\(codec=, crf=\) is deprecated: give video="):
        video = arguments.video_of(None, **keywords(codec="h265", crf=30))
    assert video == VideoSettings("h265", crf=30)
    with pytest.warns(DeprecationWarning):
        assert arguments.video_of(None, **keywords(crf=30)) is None  # no codec: no video
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert arguments.video_of(VideoSettings("av1"), **keywords()) == VideoSettings("av1")


def test_video_with_an_old_keyword_beside_it_is_refused():
    with pytest.warns(DeprecationWarning), pytest.raises(InvalidArgument, match="give video= or gop_s=, not both"):
        arguments.video_of(VideoSettings("h264"), **keywords(gop_s=1.0))
