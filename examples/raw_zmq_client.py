"""A client written from docs/protocol.md alone: pyzmq + json + numpy, no fxis_shm.

python examples/raw_zmq_client.py [tcp://127.0.0.1:5555]
"""

import itertools
import json
import sys
import time

import numpy as np
import zmq

DTYPES = {"uint8": "<u1", "uint16": "<u2", "float32": "<f4"}


class RawClient:
    def __init__(self, endpoint, timeout_s=2.0):
        self.sock = zmq.Context.instance().socket(zmq.DEALER)
        self.sock.setsockopt(zmq.LINGER, 0)  # close() never blocks on unsent requests
        self.sock.connect(endpoint)
        self.timeout_s, self.ids = timeout_s, itertools.count(1)

    def call(self, op, extra_wait_s=0.0, **fields):
        rid = next(self.ids)
        header = {"v": 1, "op": op, "id": rid, **{k: v for k, v in fields.items() if v is not None}}
        self.sock.send_multipart([b"", json.dumps(header).encode()])  # delimiter, then header
        deadline = time.monotonic() + self.timeout_s + extra_wait_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or not self.sock.poll(left * 1000):
                raise TimeoutError(f"no reply to {op!r} in time")
            frames = self.sock.recv_multipart()
            if frames and frames[0] == b"":
                frames = frames[1:]  # the delimiter we sent comes back
            reply = json.loads(frames[0])
            if reply.get("id") != rid:
                continue  # a late reply to an earlier request: discard
            if not reply["ok"]:
                raise RuntimeError(f"{reply['error']['code']}: {reply['error']['message']}")
            images = {}
            for meta in reply.get("frames", []):
                buf = frames[1 + meta["buffer"]]
                dt = np.dtype(DTYPES[meta["dtype"]])
                assert len(buf) == int(np.prod(meta["shape"])) * dt.itemsize
                images[meta["camera"]] = np.frombuffer(buf, dt).reshape(meta["shape"])
            return reply, images

    def clock_offset(self, samples=10):
        """service clock minus local CLOCK_MONOTONIC, from the fastest round trip."""
        best = None
        for _ in range(samples):
            t0 = time.monotonic_ns()
            now = self.call("time")[0]["now"]
            t1 = time.monotonic_ns()
            if best is None or t1 - t0 < best[0]:
                best = (t1 - t0, now - (t0 + t1) // 2)
        return best


def main(endpoint):
    c = RawClient(endpoint)
    rtt, offset = c.clock_offset()
    print(f"clock offset {offset} ns (+/- {rtt // 2} ns)")
    status = c.call("status")[0]
    print("cameras:", {n: (cam["kind"], cam["alive"], cam.get("shape")) for n, cam in status["cameras"].items()})
    at = time.monotonic_ns() + offset + 200_000_000  # t* = 200 ms from now, on the service's clock
    for reply, images in (c.call("tuple", extra_wait_s=0.2, at=at), c.call("tuple", sync="independent")):
        t = reply["timing"]
        print(
            f"tuple {reply['sync']}: skew {reply['skew_ns'] / 1e6:.3f} ms, "
            f"tau_w {(t['waited'] - t['received']) / 1e6:.3f} ms, "
            f"overhead {(t['sent'] - t['waited']) / 1e6:.3f} ms"
        )
        for meta in reply["frames"]:
            img = images[meta["camera"]]
            stamp = int.from_bytes(img[0].tobytes()[:8], "little")  # synthetic cameras stamp row 0
            synthetic = status["cameras"][meta["camera"]]["kind"] == "synthetic"
            print(
                f"  {meta['camera']}: frame {meta['frame_id']} eps "
                f"{(reply['t_request'] - meta['t_capture']) / 1e6:+.3f} ms {img.shape} {img.dtype}"
                + (f" stamp ok={stamp == meta['frame_id']}" if synthetic else "")
            )
    name = next(iter(status["cameras"]))
    reply, images = c.call("image", camera=name, wait="none")
    print(
        f"image {name}: frame {reply['frames'][0]['frame_id']} {images[name].shape}; latest:",
        {m["camera"]: m["frame_id"] for m in c.call("latest")[0]["frames"]},
    )
    try:
        c.call("image", camera="no-such-camera")
    except RuntimeError as exc:
        print("error reply:", exc)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "tcp://127.0.0.1:5555")
