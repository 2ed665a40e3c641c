"""A vision node of a two-host cell: one client over the services of both camera hosts,
CurveZMQ, times in this host's own clock.

    python examples/two_hosts/cell.py tcp://cams-a:5555 tcp://cams-b:5555 \\
        --server-key keys/server.key --client-key keys/vision.key_secret -n 5

For each of -n requests it asks for the tuple of every camera at "--back-ms ago" in its own
clock (time.monotonic_ns() here; the services' clocks may be anything), then prints each
service's clock estimate (offset, drift, uncertainty, how it was found), each frame's camera,
id and capture time in this clock, and the tuple's skew. JPEG with --encoding jpeg.
Exit status 0 when every tuple had every camera (and, for synthetic cameras, every frame's
stamp read back as its id), 1 otherwise.
"""

from __future__ import annotations

import argparse
import sys
import time

from fxis_shm import Client, ClientKeys, FxisError, read_stamp


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("endpoints", nargs="+", help="request endpoint of each camera host's service")
    p.add_argument("--server-key", required=True, help="the services' public key (server.key)")
    p.add_argument("--client-key", required=True, help="this node's key pair (NAME.key_secret)")
    p.add_argument("-n", type=int, default=5, help="tuples to request (default 5)")
    p.add_argument("--back-ms", type=float, default=100.0, help="ask for this long ago, ms (default 100)")
    p.add_argument("--encoding", choices=("raw", "jpeg", "png"), default="raw", help="how frames travel")
    p.add_argument("--timeout", type=float, default=10.0, help="seconds per request (default 10)")
    args = p.parse_args(argv)

    keys = ClientKeys.from_files(args.server_key, args.client_key)
    problems = 0
    with Client(args.endpoints, timeout=args.timeout, keys=keys, encoding=args.encoding) as client:
        kinds = {}
        for sub in client.clients:
            kinds.update({cam: info["kind"] for cam, info in sub.status()["cameras"].items()})
        print(f"cameras: {', '.join(sorted(kinds))}")
        for i in range(args.n):
            at = time.monotonic_ns() - int(args.back_ms * 1e6)
            try:
                pair = client.tuple(at=at)
            except FxisError as exc:
                print(f"request {i}: {type(exc).__name__}: {exc}")
                problems += 1
                continue
            parts = []
            for cam, frame in sorted(pair.items()):
                stamp_ok = kinds[cam] != "synthetic" or read_stamp(frame.image) == frame.frame_id
                problems += not stamp_ok
                parts.append(
                    f"{cam} #{frame.frame_id} at {(frame.t_capture - at) / 1e6:+.2f} ms"
                    + ("" if stamp_ok else " (STAMP MISMATCH)")
                )
            missing = set(kinds) - set(pair)
            problems += bool(missing)
            print(
                f"request {i}: skew {pair.skew_ns / 1e6:.2f} ms; "
                + "; ".join(parts)
                + (f"; MISSING {', '.join(sorted(missing))}" if missing else "")
            )
            time.sleep(0.2)
        for endpoint, c in client.clocks.items():
            print(
                f"clock of {endpoint}: {c.method}, offset {c.offset_ns / 1e9:+.6f} s, drift "
                f"{c.drift_ppm:+.2f} ppm, uncertainty {c.uncertainty_ns / 1e3:.1f} us"
            )
    print("OK" if problems == 0 else f"FAIL: {problems} problem(s)")
    return 0 if problems == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
