"""The pure check of a settings change (fxis_shm.core.tuning): typed, split by cost, all or none."""

import pytest

from fxis_shm.core.tuning import LIVE, READ_ONLY, RESTART, UNCHANGED, check_change, cost_of, describe
from fxis_shm.errors import SettingRefused

CAMERA = {
    "exposure_us": describe(10_000.0, "float", lo=10.0, hi=50_000.0, unit="us"),
    "width": describe(640, "int", RESTART, lo=16, hi=1280, inc=16),
    "pixel_format": describe("Mono8", "enum", RESTART, choices=["Mono8", "Mono12"]),
    "reverse_x": describe(False, "bool"),
    "model": describe("fake", "string", access=READ_ONLY),
}


def test_values_are_typed_rounded_to_their_step_and_split_by_cost():
    split = check_change("cam", CAMERA, {"exposure_us": "2000", "width": 650, "reverse_x": "on"})
    assert split == {LIVE: {"exposure_us": 2000.0, "reverse_x": True}, RESTART: {"width": 656}}
    assert cost_of(split) == RESTART
    assert cost_of(check_change("cam", CAMERA, {"exposure_us": 20})) == LIVE
    assert cost_of({LIVE: {}, RESTART: {}}) == UNCHANGED  # every key at its value (workers/tuning.py)
    near_max = {"width": describe(640, "int", RESTART, lo=16, hi=1275, inc=16)}
    assert check_change("cam", near_max, {"width": 1275})[RESTART] == {"width": 1264}  # never past max


@pytest.mark.parametrize(
    "asked, words",
    [
        ({"exposure_us": 5}, "exposure_us=5 is out of range: it allows 10..50000 us"),
        ({"width": 2000}, "it allows 16..1280 in steps of 16"),
        ({"pixel_format": "RGB8"}, "pixel_format='RGB8' is not one of Mono8, Mono12"),
        ({"model": "x"}, "model of camera 'cam' is read-only (now 'fake')"),
        ({"gamma": 1}, "camera 'cam' has no setting 'gamma' (it has: exposure_us, model, pixel_format"),
        ({"reverse_x": "maybe"}, "reverse_x must be true or false"),
        ({"exposure_us": float("nan")}, "exposure_us must be a finite number"),
        ({}, "no setting to change"),
    ],
)
def test_refusals_name_the_limits(asked, words):
    with pytest.raises(SettingRefused) as refused:
        check_change("cam", CAMERA, asked)
    assert words in str(refused.value)


def test_one_bad_key_refuses_the_whole_change_and_every_problem_is_named():
    with pytest.raises(SettingRefused) as refused:
        check_change("cam", CAMERA, {"exposure_us": 100, "width": 8, "gamma": 2})
    message = str(refused.value)
    assert "width=8" in message and "'gamma'" in message and "exposure_us" not in message.split(";")[0]
