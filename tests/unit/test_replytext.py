"""fxis_shm.wire.replytext writes a frame op's reply header byte for byte as
protocol.encode_reply writes the same body, and CameraFrames.frame_json a frame as the codec
writes CameraFrames.frame."""

from hypothesis import given, settings, strategies as st

from fxis_shm.core.selection import SYNC_MODES
from fxis_shm.core.snapshot import CAPTURES
from fxis_shm.wire import fastjson, protocol, replytext
from fxis_shm.wire.framemeta import CameraFrames

NS = st.integers(min_value=-(2**63), max_value=2**63 - 1)
NAMES = st.text(min_size=1, max_size=12)  # quotes, backslashes, "%", any code point
CAMERAS = st.builds(
    CameraFrames,
    NAMES,
    st.lists(st.integers(min_value=0, max_value=1 << 20), min_size=2, max_size=3),
    st.sampled_from(protocol.DTYPES),
)
FRAMES = st.tuples(
    NS, NS, NS, st.integers(min_value=0, max_value=2**64 - 1), st.none() | NS
)  # id, capture, stored, gen, available


@settings(max_examples=300)
@given(CAMERAS, FRAMES, st.integers(min_value=0, max_value=64))
def test_a_frame_is_written_as_the_codec_writes_its_dict(camera, frame, buffer):
    assert camera.frame_json(*frame, buffer) == fastjson.dumps(camera.frame(*frame, buffer=buffer)).decode()


@settings(max_examples=200)
@given(CAMERAS, FRAMES, st.integers(min_value=0, max_value=64), st.none() | NS, st.sampled_from(CAPTURES))
def test_how_a_frame_was_captured_is_written_as_the_codec_writes_it(camera, frame, buffer, t_target, capture):
    written = camera.frame_json(*frame, buffer, t_target, capture)
    assert written == fastjson.dumps(camera.frame(*frame, t_target, capture, buffer=buffer)).decode()
    assert f'"capture": "{capture}", "t_target": {t_target or "null"}' in written  # 0 and None: no target


@settings(max_examples=300)
@given(
    st.integers(min_value=0, max_value=2**63) | st.text(max_size=20),
    st.sampled_from(["image", "tuple", "latest"]),
    st.lists(st.tuples(CAMERAS, FRAMES, NS), min_size=1, max_size=4, unique_by=lambda picked: picked[0].camera),
    st.tuples(NS, NS, NS, NS, NS),
    NS,
    NS,
    st.sampled_from(SYNC_MODES),
)
def test_a_reply_is_written_as_encode_reply_writes_its_body(request_id, op, picked, timing, at, skew_ns, sync):
    searched, received, waited, copied, sent = timing
    body: dict = {"op": op}
    if op != "latest":
        body["t_request"] = at
    if op == "tuple":
        body.update(skew_ns=skew_ns, sync=sync)
    body["frames"] = [camera.frame(*frame, buffer=k) for k, (camera, frame, _) in enumerate(picked)]
    body["timing"] = {
        "searched": searched,
        "received": received,
        "waited": waited,
        "copied": copied,
        "cameras": {camera.camera: {"waited": ready} for camera, _, ready in picked},
        "sent": sent,
    }
    written = replytext.frames_reply(
        request_id,
        op,
        [camera.frame_json(*frame, k) for k, (camera, frame, _) in enumerate(picked)],
        timing,
        [(camera.name_json, ready) for camera, _, ready in picked],
        None if op == "latest" else at,
        skew_ns if op == "tuple" else None,
        sync if op == "tuple" else None,
    )
    assert written == protocol.encode_reply(request_id, body)[0]
