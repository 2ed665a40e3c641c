"""100,000 random and mutated messages at a real coordinator; afterwards it is the
same process, and it still answers well-formed requests correctly."""

import json
import random

import pytest
import zmq
from hypothesis import HealthCheck, given, settings, strategies as st

from fxis_shm import read_stamp
from fxis_shm.wire.protocol import encode_request

from .conftest import SMALL, child_pids

pytestmark = pytest.mark.integration
BATCHES, PER_BATCH = 100, 1000
TEMPLATES = [
    encode_request("tuple", id=1)[0],
    encode_request("image", id=2, camera="a")[0],
    encode_request("latest", id=3)[0],
    encode_request("status", id=4)[0],
    encode_request("sequence", id=5, kind="consecutive", camera="a", count=3)[0],
    encode_request("tuple", id=6, cameras=["a", "b"], sync="independent", wait="none")[0],
]
JUNK_VALUES = [None, True, -1, 0, 2**70, 1.5e308, "", "x" * 300, [], {}, [1, "a"], {"v": 1}]


def mutate(rng: random.Random, template: bytes) -> list[bytes]:
    kind = rng.randrange(8)
    data = bytearray(template)
    if kind == 0:  # random bytes
        return [rng.randbytes(rng.randrange(0, 200))]
    if kind == 1:  # flipped bits
        for _ in range(rng.randrange(1, 6)):
            i = rng.randrange(len(data))
            data[i] ^= 1 << rng.randrange(8)
        return [bytes(data)]
    if kind == 2:  # truncated
        return [bytes(data[: rng.randrange(len(data))])]
    if kind == 3:  # a field replaced by a value of another type
        header = json.loads(template)
        header[rng.choice(list(header) + ["camera", "cameras", "at", "count", "kind", "v"])] = rng.choice(JUNK_VALUES)
        return [json.dumps(header).encode()]
    if kind == 4:  # extra frames, empty frames
        return [bytes(data)] + [rng.randbytes(rng.randrange(0, 20)) for _ in range(rng.randrange(1, 4))]
    if kind == 5:  # spliced with another template
        other = rng.choice(TEMPLATES)
        return [bytes(data[: rng.randrange(len(data))]) + other[rng.randrange(len(other)) :]]
    if kind == 6:  # deeply nested JSON
        depth = rng.randrange(1, 2000)
        return [b"[" * depth + b"]" * depth]
    return [bytes(data)]  # a valid request now and then


@pytest.fixture(scope="module")
def service():
    import subprocess

    from fxis_shm.service.launch import ServiceProcess

    svc = ServiceProcess(
        ["--camera", f"a=synthetic:fps=50,{SMALL}", "--camera", f"b=synthetic:fps=50,{SMALL}"],
        stderr=subprocess.DEVNULL,
    ).start()
    yield svc
    svc.stop()


def test_a_fuzzed_coordinator_stays_up_and_correct(service):
    (coordinator,) = child_pids(service, "coordinator")
    sock = zmq.Context.instance().socket(zmq.DEALER)
    sock.setsockopt(zmq.LINGER, 0)
    sock.connect(service.endpoint)
    counts = {"sent": 0, "replies": 0}

    def drain(timeout_ms=0):
        while sock.poll(timeout_ms):
            sock.recv_multipart()
            counts["replies"] += 1
            timeout_ms = 0

    @settings(
        max_examples=BATCHES, deadline=None, derandomize=True, database=None, suppress_health_check=list(HealthCheck)
    )
    @given(seed=st.integers(0, 2**32 - 1), templates=st.lists(st.sampled_from(TEMPLATES), min_size=1, max_size=4))
    def batch(seed, templates):
        rng = random.Random(seed)
        for _ in range(PER_BATCH):
            assert sock.poll(10_000, zmq.POLLOUT), "the coordinator stopped taking messages"
            sock.send_multipart([b""] + mutate(rng, rng.choice(templates)), flags=zmq.NOBLOCK)
            counts["sent"] += 1
            drain()
        drain(50)

    try:
        batch()
        drain(500)
    finally:
        sock.close()
    assert counts["sent"] >= 100_000
    # most got an answer; the rest were dropped by the bounded reply queue while we sent faster than we read
    assert counts["replies"] > counts["sent"] * 0.5
    assert child_pids(service, "coordinator") == [coordinator]  # never crashed, never restarted
    with service.client() as client:
        frames = client.tuple()
        assert all(read_stamp(f.image) == f.frame_id for f in frames.values())
        status = client.status()
    assert status["supervisor"]["processes"]["coordinator"]["restarts"] == 0
    print(f"fuzz: {counts['sent']} messages sent, {counts['replies']} replies; coordinator pid {coordinator} unchanged")
