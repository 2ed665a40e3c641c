"""The typed, versioned specs the supervisor gives its children (fxis_shm.service.childspec)."""

from __future__ import annotations

import json

import pytest

from fxis_shm.errors import SpecError
from fxis_shm.service.childspec import ROLES, CameraWorkerSpec, CoordinatorSpec, DashboardSpec, FoxgloveSpec, Ros2Spec

CAMERA = CameraWorkerSpec(
    service="svc",
    camera="left",
    kind="synthetic",
    options={"fps": 20.0},
    slots=4,
    time_origin_ns=123,
    log_level="DEBUG",
)
COORDINATOR = CoordinatorSpec(
    service="svc",
    endpoint="tcp://127.0.0.1:1",
    pub="tcp://127.0.0.1:2",
    events="tcp://127.0.0.1:3",
    cameras={"left": "synthetic"},
    settings={"timeout_ms": 50.0},
)


@pytest.mark.parametrize("spec", [CAMERA, COORDINATOR])
def test_a_spec_survives_its_trip_through_json(spec):
    assert type(spec).from_json(spec.to_json()) == spec


def test_the_command_runs_the_role_module_with_the_spec_and_the_ready_fd():
    command = CAMERA.command(7)
    assert command[1:3] == ["-m", "fxis_shm.workers.camera"]
    assert json.loads(command[3])["role"] == "camera" and command[4] == "7"


def edited(spec, **changes) -> str:
    data = json.loads(spec.to_json())
    for key, value in changes.items():
        if value is None:
            del data[key]
        else:
            data[key] = value
    return json.dumps(data)


@pytest.mark.parametrize(
    "text, words",
    [
        (edited(CAMERA, version=99), ["version 99", f"reads version {CameraWorkerSpec.VERSION}", "different installs"]),
        (edited(CAMERA, version=None), ["version None"]),
        (edited(CAMERA, role="coordinator"), ["camera process", "'coordinator'"]),
        (edited(CAMERA, slots="4"), ["'slots'", "int", "'4'"]),
        (edited(CAMERA, slots=True), ["'slots'"]),
        (edited(CAMERA, options=[1]), ["'options'", "dict"]),
        (edited(CAMERA, camera=None), ["missing field(s) ['camera']"]),
        (edited(CAMERA, colour="red"), ["unknown field(s) ['colour']"]),
        ("{not json", ["not JSON"]),
        ("[1, 2]", ["JSON object"]),
    ],
)
def test_a_spec_that_does_not_fit_is_refused_with_what_is_wrong(text, words):
    with pytest.raises(SpecError) as info:
        CameraWorkerSpec.from_json(text)
    assert all(w in str(info.value) for w in words), str(info.value)


@pytest.mark.parametrize(
    "changes, words",
    [
        ({"cameras": {"left": 1}}, ["'cameras'"]),
        ({"curve_secret": 5}, ["'curve_secret'", "str | None"]),
        ({"settings": {"timeout_ms": None}}, None),  # settings hold any JSON value
        ({"curve_secret": None}, None),  # a default field may be left out
    ],
)
def test_coordinator_fields_are_checked_by_type(changes, words):
    text = edited(COORDINATOR, **changes)
    if words is None:
        CoordinatorSpec.from_json(text)
        return
    with pytest.raises(SpecError) as info:
        CoordinatorSpec.from_json(text)
    assert all(w in str(info.value) for w in words), str(info.value)


def test_roles_name_their_spec_classes():
    assert ROLES == {
        "camera": CameraWorkerSpec,
        "coordinator": CoordinatorSpec,
        "dashboard": DashboardSpec,
        "foxglove": FoxgloveSpec,
        "ros2": Ros2Spec,
    }
