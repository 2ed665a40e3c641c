"""What a real ROS 2 node on this host receives from `fxis run --ros2`, beside the anchor: a plain
rclpy publisher (Fast DDS) sending the same images to the same node (issue 32's load figure).

    .venv/bin/python bench/compare/ros2_bridge.py                      # 4 x 1360x1024 mono8 at 30 fps, 10 s each
    .venv/bin/python bench/compare/ros2_bridge.py --cameras 2 --seconds 20 --ways rclpy,anchor,cyclone

Each way runs alone, in a network namespace holding only loopback (Fast DDS's default discovery
multicasts): the node is bench/compare/rclpy/listener.py, default-configured (Fast DDS, reliable, keep last
10), in .venv-ros (make ros-venvs). Ways: ``rclpy`` (the bridge on rclpy, ``--ros2-via rclpy``),
``cyclone`` (the bridge on plain Cyclone DDS, the no-ROS path: over UDP, into the node's default
receive buffer), ``anchor`` (bench/compare/rclpy/publisher.py). Printed per way: frames/s per camera, id
gaps, empty images, the images' age on arrival (median, p99), the node's CPU, and the publisher's
CPU (the bridge process, or the anchor) per MB delivered. JSON in bench/results/ros2_bridge.json.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
if not __package__:  # run as a script (python bench/compare/ros2_bridge.py): the project root on the path
    sys.path.insert(0, ROOT)  # for bench.* and tests.hosts

from bench.shared.cpu import cpu_ticks  # noqa: E402
from fxis_shm import Client  # noqa: E402
from fxis_shm.service.launch import ServiceProcess  # noqa: E402
from tests.dds_peer import ROS_VENVS, ros_environment  # noqa: E402
from tests.hosts import LoopbackNamespace  # noqa: E402

NS = "/loadcell"
# the node and the anchor, run by the ROS 2 venv's Python
RCLPY_SCRIPTS = {
    name: os.path.join(ROOT, "bench", "compare", "rclpy", f"{name}.py") for name in ("listener", "publisher")
}
DOMAIN = 201


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cameras", type=int, default=4)
    p.add_argument("--width", type=int, default=1360)
    p.add_argument("--height", type=int, default=1024)
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--seconds", type=float, default=10.0, help="measured seconds per way (after 2 s of warm-up)")
    p.add_argument("--ways", default="rclpy,anchor", help="comma-separated: rclpy, cyclone, anchor")
    p.add_argument("--out", default=os.path.join(ROOT, "bench", "results", "ros2_bridge.json"))
    return p


def cpu_seconds(pid: int) -> float:
    ticks = cpu_ticks(pid)
    return (ticks or 0) / os.sysconf("SC_CLK_TCK")


def ros_python() -> str:
    python = ROS_VENVS["kilted"] / "bin" / "python"
    if not python.exists():
        raise SystemExit(f"no ROS 2 venv at {python.parent.parent}: run make ros-venvs")
    return str(python)


def read_line(proc: subprocess.Popen, timeout: float) -> str | None:
    """The process's next stdout line, or None if none came within ``timeout`` s."""
    import selectors

    assert proc.stdout is not None
    with selectors.DefaultSelector() as selector:
        selector.register(proc.stdout, selectors.EVENT_READ)
        if not selector.select(timeout):
            return None
    return proc.stdout.readline()


def end(proc: subprocess.Popen | None) -> None:
    """SIGTERM, then SIGKILL after 5 s: a wedged node ignores SIGTERM (issue 32 saw one)."""
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(5)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def run_way(way: str, args, host: LoopbackNamespace, tmp: str) -> dict:
    topics = ",".join(f"{NS}/cam{i}/image_raw" for i in range(args.cameras))
    env = ros_environment(ROS_VENVS["kilted"])
    node = subprocess.Popen(
        [*host.wrapper(), ros_python(), RCLPY_SCRIPTS["listener"], "--topics", topics,
         "--seconds", str(args.seconds), "--domain", str(DOMAIN)],
        stdout=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    publisher_pid: int
    svc = None
    anchor = None
    try:
        if way == "anchor":
            anchor = subprocess.Popen(
                [*host.wrapper(), ros_python(), RCLPY_SCRIPTS["publisher"], "--topics", topics,
                 "--width", str(args.width), "--height", str(args.height), "--fps", str(args.fps),
                 "--seconds", str(args.seconds + 30), "--domain", str(DOMAIN)],
                stdout=subprocess.PIPE, text=True, env=env,
            )  # fmt: skip
            publisher_pid = anchor.pid
        else:
            cameras = []
            for i in range(args.cameras):
                size = f"width={args.width},height={args.height},fps={args.fps:g}"
                cameras += ["--camera", f"cam{i}=synthetic:{size},phase_ms={i * 3}"]
            extra = ["--ros2-python", ros_python()] if way == "rclpy" else []
            endpoints = {k: f"ipc://{tmp}/{way}-{k}" for k in ("endpoint", "pub", "events")}
            svc = ServiceProcess(
                [*cameras, "--slots", "30", "--ros2", "--ros2-domain", str(DOMAIN), "--ros2-namespace", NS,
                 "--ros2-via", way, *extra],
                wrapper=host.wrapper(), env={k: v for k, v in os.environ.items() if k != "CYCLONEDDS_URI"},
                stderr=subprocess.DEVNULL, **endpoints,
            ).start()  # fmt: skip
            with Client(svc.endpoint) as client:
                deadline = time.monotonic() + 30
                while not (client.status().get("ros2") or {}).get("pid"):
                    if time.monotonic() > deadline:
                        raise SystemExit("the bridge did not report within 30 s")
                    time.sleep(0.2)
                publisher_pid = client.status()["ros2"]["pid"]
        line = read_line(node, 60 + 2)  # the node waits up to 60 s for every camera's first image
        if line is None or line.strip() != "measuring":
            return {"way": way, "failed": f"the node received no image of some camera ({line!r})"}
        cpu0, t0 = cpu_seconds(publisher_pid), time.monotonic()
        line = read_line(node, args.seconds + 15)
        if not line:
            return {"way": way, "failed": "the node did not report: wedged (issue 32 saw one at 100 % CPU)"}
        result = json.loads(line)
        publisher_cpu = cpu_seconds(publisher_pid) - cpu0
        span = time.monotonic() - t0
        dropped = None
        if svc is not None:
            with Client(svc.endpoint) as client:
                dropped = sum(c["frames_dropped"] for c in client.status()["cameras"].values())
    finally:
        end(node)
        end(anchor)
        if svc is not None:
            svc.stop()
    frames = sum(c["frames"] for c in result["cameras"].values())
    megabytes = frames * args.width * args.height / 1e6
    result.update(
        way=way,
        publisher_cpu_pct=100 * publisher_cpu / span,
        publisher_cpu_ms_per_mb=1000 * publisher_cpu / megabytes if megabytes else None,
        node_cpu_pct=100 * result["node_cpu_s"] / result["seconds"],
        megabytes_per_s=megabytes / result["seconds"],
        camera_frames_dropped=dropped,
    )
    return result


def table(results: list[dict]) -> str:
    failed = [f"{r['way']}: {r['failed']}" for r in results if "failed" in r]
    results = [r for r in results if "failed" not in r]
    rows = [
        ("frames/s per camera (min)", lambda r: f"{min(c['fps'] for c in r['cameras'].values()):.1f}"),
        ("id gaps (all cameras)", lambda r: str(sum(c["gaps"] for c in r["cameras"].values()))),
        ("empty images", lambda r: str(sum(c["empty"] for c in r["cameras"].values()))),
        ("age median ms (max of cameras)", lambda r: f"{max(c['age_median_ms'] for c in r['cameras'].values()):.1f}"),
        ("age p99 ms (max of cameras)", lambda r: f"{max(c['age_p99_ms'] for c in r['cameras'].values()):.1f}"),
        ("MB/s delivered", lambda r: f"{r['megabytes_per_s']:.0f}"),
        ("node CPU %", lambda r: f"{r['node_cpu_pct']:.0f}"),
        ("publisher CPU %", lambda r: f"{r['publisher_cpu_pct']:.0f}"),
        ("publisher CPU ms per MB", lambda r: f"{r['publisher_cpu_ms_per_mb']:.2f}"),
        ("camera frames dropped", lambda r: str(r.get("camera_frames_dropped", "-")).replace("None", "-")),
    ]  # fmt: skip
    names = {"rclpy": "bridge (rclpy)", "cyclone": "bridge (Cyclone)", "anchor": "anchor (rclpy pub)"}
    width = max(len(label) for label, _ in rows)
    lines = [f"{'':{width}}  " + "  ".join(f"{names[r['way']]:>19}" for r in results)]
    for label, cell in rows:
        lines.append(f"{label:{width}}  " + "  ".join(f"{cell(r):>19}" for r in results))
    return "\n".join(lines + failed)


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    ways = [w for w in args.ways.split(",") if w]
    unknown = set(ways) - {"rclpy", "cyclone", "anchor"}
    if unknown:
        parser().error(f"unknown ways: {', '.join(sorted(unknown))}")
    print(
        f"{args.cameras} x {args.width}x{args.height} mono8 at {args.fps:g} fps to a default-configured reliable "
        f"rclpy node (Fast DDS) on this host, {args.seconds:g} s per way; load average {os.getloadavg()[0]:.1f} "
        f"on {os.cpu_count()} cores",
        flush=True,
    )
    results = []
    with tempfile.TemporaryDirectory(prefix="fxis-ros2-load-") as tmp, LoopbackNamespace() as host:
        for way in ways:
            results.append(run_way(way, args, host, tmp))
            print(f"  {way}: done", flush=True)
    print(table(results))
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump({"args": vars(args), "results": results}, f, indent=1)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
