"""bench/network/remote.py's clock watch: every remote client's clock estimate sampled in the
background against the true offset of its emulated host, and the table of the errors."""

from __future__ import annotations

import threading
import time

from bench.shared import common
from fxis_shm import Client

CLOCK_TARGET_MS = 0.1


class ClockWatch:
    """Samples every watched client's estimate for an endpoint against the true offset."""

    def __init__(self, every_s: float):
        self.every_s, self.samples, self.started = every_s, [], None
        self._watched: list[tuple[str, Client, str, int]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="clock-watch", daemon=True)

    def watch(self, label: str, client: Client, endpoint: str, true_offset_ns: int) -> None:
        if endpoint not in client.clocks:  # the first estimates here: the thread then only reads them
            raise ValueError(f"{label}: the client does not ask {endpoint}")
        self._watched.append((label, client, endpoint, true_offset_ns))
        if self.started is None:
            self.started = time.monotonic()
            self._thread.start()

    def unwatch(self, client: Client) -> None:
        self._watched = [w for w in self._watched if w[1] is not client]

    def _loop(self) -> None:
        while not self._stop.wait(self.every_s):
            for label, client, endpoint, true in list(self._watched):
                estimate = client.clocks.get(endpoint)
                if estimate is None or estimate.method != "estimated":
                    continue
                now = time.monotonic_ns()
                error = estimate.to_service(now) - now - true
                self.samples.append(
                    {
                        "t": now,
                        "client": label,
                        "endpoint": endpoint,
                        "error_ns": error,
                        "uncertainty_ns": estimate.uncertainty_ns,
                        "drift_ppm": estimate.drift_ppm,
                    }
                )

    def elapsed_s(self) -> float:
        return 0.0 if self.started is None else time.monotonic() - self.started

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5)

    def report(self) -> dict:
        keys = sorted({(s["client"], s["endpoint"]) for s in self.samples})
        rows = {f"{c} {e}": [s for s in self.samples if (s["client"], s["endpoint"]) == (c, e)] for c, e in keys}
        rows["all"] = self.samples
        out = {}
        for name, samples in rows.items():
            out[name] = {
                "abs_error_ms": common.summary(abs(common.ms(s["error_ns"])) for s in samples),
                "uncertainty_ms": common.summary(common.ms(s["uncertainty_ns"]) for s in samples),
            }
        p99 = out["all"]["abs_error_ms"]["p99"]
        out["target"] = {
            "p99_abs_error_ms": p99,
            "limit_ms": CLOCK_TARGET_MS,
            "watched_s": self.elapsed_s(),
            "passed": None if p99 is None else p99 <= CLOCK_TARGET_MS,
        }
        return out


def print_clock(report: dict, minutes: float) -> None:
    rows = [
        [
            name,
            r["abs_error_ms"]["n"],
            r["abs_error_ms"]["median"],
            r["abs_error_ms"]["p99"],
            r["abs_error_ms"]["max"],
            r["uncertainty_ms"]["median"],
        ]
        for name, r in report.items()
        if name != "target"
    ]
    print(
        common.table(
            ["client endpoint", "samples", "|err| median", "p99", "max", "uncert. median"],
            rows,
            title="clock estimate error against the true offset, ms",
            digits=4,
        )
    )
    t = report["target"]
    watched = t["watched_s"] / 60
    print(
        f"  {common.verdict(t['passed'])} clock: p99 |error| {common.fmt(t['p99_abs_error_ms'], 4)} <= "
        f"{CLOCK_TARGET_MS} ms over {watched:.1f} min"
        + ("" if watched >= minutes - 1e-9 else f" (short of --minutes {minutes:g})")
    )
