"""The receiving side of bench/compare/ros2_bridge.py: a default-configured rclpy node (reliable, keep last 10)
subscribed to N cameras' image_raw; runs in a ROS 2 venv (.venv-ros), imports nothing of fxis.

After the first image of every camera and ``--warmup`` seconds, it counts for ``--seconds``: images,
gaps in the frame ids (the 8-byte id and its complement at the start of the first row), zero-length
images, and the age of each image on arrival (now - header.stamp, both the system clock). Prints
``measuring`` when it starts, then one JSON line of results, including its own CPU seconds.
"""

import argparse
import json
import statistics
import sys
import time

import rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import Image


def frame_id(data: memoryview) -> int | None:
    if len(data) < 16:
        return None
    value = int.from_bytes(data[:8], "little")
    return value if int.from_bytes(data[8:16], "little") == value ^ (2**64 - 1) else None


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--topics", required=True, help="comma-separated image topics")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--warmup", type=float, default=2.0)
    parser.add_argument("--domain", type=int, required=True)
    args = parser.parse_args()
    rclpy.init(domain_id=args.domain)
    node = rclpy.create_node("fxis_bench_listener")
    topics = args.topics.split(",")
    stats = {t: {"frames": 0, "gaps": 0, "empty": 0, "ages": [], "last": None} for t in topics}
    state = {"measuring": False}

    def on_image(topic):
        def callback(msg: Image) -> None:
            now = time.time_ns()
            s = stats[topic]
            data = memoryview(msg.data)
            ident = frame_id(data)
            if s["last"] is not None and ident is not None and ident > s["last"] + 1 and state["measuring"]:
                s["gaps"] += ident - s["last"] - 1
            if ident is not None:
                s["last"] = ident
            if not state["measuring"]:
                return
            s["frames"] += 1
            s["empty"] += len(data) == 0
            s["ages"].append((now - (msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)) / 1e6)

        return callback

    subs = [node.create_subscription(Image, t, on_image(t), QoSProfile(depth=10)) for t in topics]
    deadline = time.monotonic() + 60
    while any(s["last"] is None for s in stats.values()) and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    end_warmup = time.monotonic() + args.warmup
    while time.monotonic() < end_warmup:
        rclpy.spin_once(node, timeout_sec=0.05)
    state["measuring"] = True
    print("measuring", flush=True)
    cpu0, t0 = time.process_time(), time.monotonic()
    while time.monotonic() < t0 + args.seconds:
        rclpy.spin_once(node, timeout_sec=0.05)
    cpu, span = time.process_time() - cpu0, time.monotonic() - t0
    result = {"seconds": span, "node_cpu_s": cpu, "cameras": {}}
    for topic, s in stats.items():
        ages = sorted(s["ages"]) or [float("nan")]
        result["cameras"][topic] = {
            "fps": s["frames"] / span,
            "frames": s["frames"],
            "gaps": s["gaps"],
            "empty": s["empty"],
            "age_median_ms": statistics.median(ages),
            "age_p99_ms": ages[min(len(ages) - 1, int(0.99 * len(ages)))],
        }
    print(json.dumps(result), flush=True)
    del subs
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
