"""GigE Vision action commands over real UDP on loopback: fxis_shm/client/actions.py's sender
against the project's responder (tests/gvcp_responder.py), which fires a real Aravis fake
camera (arv-fake-gv-camera-0.8, software-triggered) at the time of its own device clock.

Addresses of their own (127.0.0.34 the camera, 127.0.0.35 the responder), so that the suite's
emulators on 127.0.0.1 and 127.0.0.2, port 3956, are not disturbed."""

import json
import socket
import time

import pytest

from fxis_shm.client.actions import ActionFailed, ActionSender, check
from fxis_shm.core.ptp import ClockNotLocked
from fxis_shm.wire import gvcp_action as gvcp

from ..aravis_trigger import TriggeredCamera
from ..gvcp_responder import ActionResponder
from ..hosts import loopback_address

pytestmark = pytest.mark.integration
CAMERA_ADDRESS, DEVICE_ADDRESS = "127.0.0.34", "127.0.0.35"
KEYS = dict(device_key=0x0FEEDBAC, group_key=7, group_mask=0x3)
OFFSET_NS = 1000 * 10**9  # the device clock runs 1000 s ahead of the host's
# How far ahead actions are scheduled: the command's way to the device (a resend after a lost
# copy included) must end before T however long a loaded machine holds up the sender or the
# responder (both threads of this process: seen up to 1.5 s), else the device answers ACTION_LATE
LEAD_NS = 3_000_000_000
FIRE_TIMEOUT_S = LEAD_NS / 1e9 + 5  # for the action to fire, T included


@pytest.fixture(scope="module")
def addresses():
    with loopback_address(CAMERA_ADDRESS), loopback_address(DEVICE_ADDRESS):
        yield CAMERA_ADDRESS, DEVICE_ADDRESS


@pytest.fixture
def camera(addresses, emulator):
    emu = emulator(CAMERA_ADDRESS, debug="device:3")  # each control command it handled, timed, in its log
    cam = TriggeredCamera(emu.device_id)
    cam.emulator = emu  # its log, for a failure's message
    yield cam
    cam.close()


@pytest.fixture
def responder(addresses):
    """``responder(**options)``: an ActionResponder on DEVICE_ADDRESS:3956, closed at teardown."""
    opened = []

    def open_one(**options):
        options = {**KEYS, "clock_offset_ns": OFFSET_NS, **options}
        device = ActionResponder(DEVICE_ADDRESS, **options).__enter__()
        opened.append(device)
        return device

    yield open_one
    for device in opened:
        device.__exit__(None, None, None)


@pytest.fixture
def sender():
    with ActionSender(KEYS["device_key"], KEYS["group_key"], 0x1, retries=2) as s:
        yield s


@pytest.fixture
def patient_sender():
    """A sender whose copies (one per 200 ms ACK timeout) go on for over 2 s, well within
    LEAD_NS: a responder held up for a while still answers one of them before T."""
    with ActionSender(KEYS["device_key"], KEYS["group_key"], 0x1, retries=10) as s:
        yield s


def timed(camera, calls: list):
    """``camera.trigger``, each call's moment, length and the emulator's scheduling around it
    kept in ``calls``: make test run 48 and stop 52's CI saw the trigger's write time out (Aravis'
    5 tries of 500 ms) with nothing in the emulator's warnings; this says which side was silent."""

    def trigger():
        started, before, raised = time.time(), camera.emulator.scheduling(), None
        try:
            camera.trigger()
        except Exception as exc:
            raised = str(exc)
            raise
        finally:
            clock = time.strftime("%H:%M:%S", time.gmtime(started)) + f".{int(started * 1000) % 1000:03d}"
            took = round(time.time() - started, 3)
            emulator = [before, camera.emulator.scheduling()]
            calls.append({"started": clock, "took_s": took, "raised": raised, "emulator": emulator})

    return trigger


def test_a_scheduled_action_fires_the_camera_at_the_device_clocks_time_and_its_frame_arrives(
    camera, responder, patient_sender
):
    calls: list[dict] = []
    device = responder(fire=timed(camera, calls))
    at = device.now() + LEAD_NS
    outcome = check(patient_sender.fire([DEVICE_ADDRESS], action_time=at))[DEVICE_ADDRESS]
    assert outcome.status == gvcp.STATUS_SUCCESS
    [fired] = device.wait_fired(1, timeout=FIRE_TIMEOUT_S)
    assert fired.action_time == at and fired.called_ns >= at  # never early, on the device's clock
    said = {"control lost": camera.control_lost.is_set(), "trigger": calls, "emulator": camera.emulator.log()[-40:]}
    assert device.errors == [], json.dumps(said, indent=1)  # a string: pytest shortens the repr of a dict
    frame = camera.frame(timeout=5)
    assert frame is not None, "the triggered frame never arrived"
    arrived_host_ns, _block = frame
    assert arrived_host_ns >= at - OFFSET_NS  # exposed after T (T in the host's clock)


def test_an_immediate_action_fires_at_once(camera, responder, sender):
    device = responder(fire=camera.trigger)
    sent = device.now()
    assert check(sender.fire([DEVICE_ADDRESS]))[DEVICE_ADDRESS].ok
    [fired] = device.wait_fired(1, timeout=5)
    assert fired.action_time is None and fired.called_ns >= sent
    assert device.received[0].action_time is None  # no time on the wire, no scheduled flag
    assert camera.frame(timeout=5) is not None


def test_a_time_already_past_is_answered_late_and_nothing_fires(responder, sender):
    device = responder()
    outcome = sender.fire([DEVICE_ADDRESS], action_time=device.now() - 1_000_000)[DEVICE_ADDRESS]
    assert outcome.status == gvcp.STATUS_ACTION_LATE
    assert "GEV_STATUS_ACTION_LATE" in outcome.error and "already past" in outcome.error
    assert device.fired == []  # answered before anything was queued
    with pytest.raises(ActionFailed, match=f"{DEVICE_ADDRESS}: GEV_STATUS_ACTION_LATE"):
        check({DEVICE_ADDRESS: outcome})


def test_a_device_whose_clock_is_not_locked_answers_no_reference_time(responder, sender):
    device = responder(locked=False)
    outcome = sender.fire([DEVICE_ADDRESS], action_time=device.now() + LEAD_NS)[DEVICE_ADDRESS]
    assert outcome.status == gvcp.STATUS_NO_REF_TIME and "not locked to a PTP master" in outcome.error
    assert device.fired == []
    assert sender.fire([DEVICE_ADDRESS])[DEVICE_ADDRESS].ok  # an immediate action needs no clock


def test_a_full_queue_of_scheduled_actions_answers_overflow(responder, sender):
    device = responder(queue_size=1)
    far = device.now() + 60 * 10**9
    assert sender.fire([DEVICE_ADDRESS], action_time=far)[DEVICE_ADDRESS].ok
    outcome = sender.fire([DEVICE_ADDRESS], action_time=far + 1)[DEVICE_ADDRESS]
    assert outcome.status == gvcp.STATUS_OVERFLOW and "queue of scheduled actions is full" in outcome.error


def test_no_answer_is_retried_then_reported(responder, sender):
    device = responder(group_key=8)  # not our group: a device drops it without an answer
    outcome = sender.fire([DEVICE_ADDRESS])[DEVICE_ADDRESS]
    assert outcome.status is None and outcome.attempts == 3  # the first send and 2 retries
    assert outcome.error == f"{DEVICE_ADDRESS}: no ACTION_ACK after 3 attempt(s)"
    assert [c.req_id for c in device.received] == [device.received[0].req_id] * 3  # resent unchanged
    assert device.fired == []


def test_a_lost_command_is_resent_and_fires_once(responder, patient_sender):
    device = responder()
    device.ignore_next = 1  # the first copy is lost on the way
    at = device.now() + LEAD_NS
    outcome = patient_sender.fire([DEVICE_ADDRESS], action_time=at)[DEVICE_ADDRESS]
    assert outcome.ok and outcome.attempts >= 2  # more if the machine delayed an ACK past the timeout
    assert [f.action_time for f in device.wait_fired(1, timeout=FIRE_TIMEOUT_S)] == [at]


def test_a_retransmission_the_device_already_had_is_answered_again_and_not_carried_out_twice(responder, sender):
    device = responder()
    packet = gvcp.ActionCommand(**KEYS, req_id=4242).encode()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
        raw.settimeout(5)
        for _ in range(2):  # the same command twice, as a sender that missed the first ACK resends it
            raw.sendto(packet, (DEVICE_ADDRESS, gvcp.GVCP_PORT))
            assert gvcp.ActionAck.decode(raw.recv(64)) == gvcp.ActionAck(gvcp.STATUS_SUCCESS, 4242)
    assert len(device.received) == 2
    device.wait_fired(1, timeout=5)
    # one more action through the sender: it fires as the second, so the copy never fired
    assert check(sender.fire([DEVICE_ADDRESS]))
    assert len(device.wait_fired(2, timeout=5)) == 2 and len(device.fired) == 2


def test_the_fake_camera_has_no_ptp_features_and_a_scheduled_action_to_it_is_refused_saying_why(
    camera, responder, sender
):
    ptp = camera.ptp()
    assert not ptp.available and not ptp.locked
    device = responder(fire=camera.trigger)
    with pytest.raises(ClockNotLocked, match=f"{DEVICE_ADDRESS}: it has no PTP features"):
        sender.fire([DEVICE_ADDRESS], action_time=device.now() + LEAD_NS, clocks={DEVICE_ADDRESS: ptp})
    assert device.received == []  # refused before anything was sent
    assert sender.fire([DEVICE_ADDRESS], clocks={DEVICE_ADDRESS: ptp})[DEVICE_ADDRESS].ok  # immediate: allowed


def test_the_fake_camera_itself_does_not_answer_action_commands(camera):
    """Why the responder exists: arv-fake-gv-camera-0.8 ignores ACTION_CMD."""
    with ActionSender(1, 1, 1, timeout_s=0.2, retries=1) as s:
        assert s.fire([CAMERA_ADDRESS])[CAMERA_ADDRESS].status is None


def test_one_packet_via_another_address_collects_the_acks_of_the_devices_named(responder, sender):
    """``via=`` is for a broadcast address (lo has none: here the device's own address stands
    in): one packet per attempt, and the ACKs awaited are those of the devices listed."""
    device = responder()
    outcomes = sender.fire([DEVICE_ADDRESS, "127.0.0.99"], via=DEVICE_ADDRESS)
    assert outcomes[DEVICE_ADDRESS].ok
    assert outcomes["127.0.0.99"].status is None and outcomes["127.0.0.99"].attempts == 3
    assert len(device.received) == 3  # every attempt went via the one address, answered each time
