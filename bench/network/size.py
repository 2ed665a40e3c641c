"""bench/network/remote.py's part size: round trip and link bytes per tuple, raw against JPEG, over
host A's link shaped to 1 Gbit and to 100 Mbit."""

from __future__ import annotations

import time

from bench.shared import common
from fxis_shm import Client

RATIO_TARGETS = {"1gbit": 0.6, "100mbit": 0.25}


def sizes(args, host, clients: dict[str, Client], cams: list[str]) -> dict:
    out = {"configs": {}, "targets": []}
    rows = []
    for rate in RATIO_TARGETS:
        host.set_rate(rate)
        for encoding, client in clients.items():
            client.tuple(cams, wait="none")  # warm up: the link's queue and the encoder's
            rtts, before = [], host.link_bytes()["from_host"]
            for _ in range(args.size_requests):
                sent = time.monotonic_ns()
                client.tuple(cams, wait="none")
                rtts.append(common.ms(time.monotonic_ns() - sent))
            per_request = (host.link_bytes()["from_host"] - before) / args.size_requests
            out["configs"][f"{rate} {encoding}"] = {"rtt_ms": common.summary(rtts), "link_bytes": per_request}
            rows.append(
                [
                    f"{rate} {encoding}",
                    args.size_requests,
                    common.summary(rtts)["mean"],
                    common.summary(rtts)["p99"],
                    per_request / 1e6,
                ]
            )
    host.set_rate("1gbit")
    print()
    print(
        common.table(
            ["link encoding", "n", "rtt mean", "p99", "MB/tuple"],
            rows,
            title=f"round trip (ms) and link bytes per tuple of {' + '.join(cams)} "
            f"({args.width}x{args.height} mono8), raw and JPEG q{args.quality}",
            digits=3,
        )
    )
    for rate, limit in RATIO_TARGETS.items():
        raw, jpeg = (out["configs"][f"{rate} {e}"] for e in clients)
        ratio = jpeg["rtt_ms"]["mean"] / raw["rtt_ms"]["mean"]
        bytes_ratio = jpeg["link_bytes"] / raw["link_bytes"] if raw["link_bytes"] else None
        passed = ratio <= limit
        out["targets"].append(
            {"rate": rate, "rtt_ratio": ratio, "bytes_ratio": bytes_ratio, "limit": limit, "passed": passed}
        )
        print(
            f"  {common.verdict(passed)} {rate}: JPEG/raw round trip {ratio:.3f}x <= {limit}x "
            f"(bytes {common.fmt(bytes_ratio, 3)}x)"
        )
    return out
