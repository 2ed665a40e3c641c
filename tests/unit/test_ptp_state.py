"""A camera's PTP state from its GenICam features (fxis_shm/core/ptp.py), with the features
given as a dict: the names cameras use, the latch some need first, and the refusal's words."""

import pytest

from fxis_shm.core.ptp import ClockNotLocked, PtpState, read_ptp, require_locked


def state_of(features: dict[str, str], commands=()) -> tuple[PtpState, list[str]]:
    executed: list[str] = []

    def execute(name: str) -> bool:
        executed.append(name)
        return name in commands

    return read_ptp(features.get, execute), executed


def test_sfnc_features_after_the_latch():
    state, executed = state_of(
        {"PtpEnable": "true", "PtpStatus": "Slave", "PtpOffsetFromMaster": "-42"}, commands={"PtpDataSetLatch"}
    )
    assert executed == ["PtpDataSetLatch"]  # latched once, the other name not tried
    assert state == PtpState(enabled=True, status="Slave", offset_ns=-42)
    assert state.locked and state.why_not_locked() is None
    status = state.as_status()
    assert status == {"available": True, "enabled": True, "status": "Slave", "offset_ns": -42, "locked": True}


def test_gige_vision_features_of_older_cameras():
    state, executed = state_of({"GevIEEE1588": "1", "GevIEEE1588Status": "Master"})
    assert executed == ["PtpDataSetLatch", "GevIEEE1588DataSetLatch"]  # neither exists: no latch
    assert state.locked and state.offset_ns is None


@pytest.mark.parametrize(
    "features, words",
    [
        ({}, "has no PTP features"),
        ({"PtpEnable": "false", "PtpStatus": "Disabled"}, "PTP is disabled"),
        ({"PtpEnable": "true", "PtpStatus": "Listening"}, "its PTP state is Listening, not Slave or Master"),
        ({"PtpEnable": "true", "PtpStatus": "Uncalibrated"}, "Uncalibrated"),
        ({"PtpEnable": "true"}, "its PTP state is unknown"),
    ],
)
def test_a_clock_that_is_not_locked_says_why(features, words):
    state, _ = state_of(features)
    assert not state.locked
    assert words in state.why_not_locked()


def test_a_scheduled_action_is_refused_naming_each_unlocked_camera():
    locked = PtpState(enabled=True, status="Slave")
    listening = PtpState(enabled=True, status="Listening")
    require_locked({"left": locked})  # nothing to refuse
    with pytest.raises(ClockNotLocked) as refused:
        require_locked({"left": locked, "right": listening, "top": PtpState()})
    message = str(refused.value)
    assert message.startswith("scheduled action refused: right: its PTP state is Listening")
    assert "top: it has no PTP features" in message and "left" not in message
