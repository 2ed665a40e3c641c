"""The anchor of bench/compare/ros2_bridge.py: a plain rclpy publisher (Fast DDS, default QoS(10)) sending N
cameras' images at a rate, as a Python camera driver on ROS 2 does (a new Image a frame, its data
the frame's bytes). Each frame carries its id as the listener reads it (8 bytes and their
complement at the start of the first row). Runs in a ROS 2 venv; prints its CPU seconds at the end.
"""

import argparse
import json
import sys
import time

import numpy as np
import rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import Image


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--topics", required=True)
    parser.add_argument("--width", type=int, default=1360)
    parser.add_argument("--height", type=int, default=1024)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--seconds", type=float, required=True)
    parser.add_argument("--domain", type=int, required=True)
    args = parser.parse_args()
    rclpy.init(domain_id=args.domain)
    node = rclpy.create_node("fxis_bench_anchor")
    publishers = [node.create_publisher(Image, t, QoSProfile(depth=10)) for t in args.topics.split(",")]
    frame = np.random.default_rng(0).integers(0, 255, (args.height, args.width), np.uint8)
    period = 1.0 / args.fps
    start = time.monotonic()
    cpu0 = time.process_time()
    k = 0
    while time.monotonic() < start + args.seconds and rclpy.ok():
        stamp = np.array([k, k ^ (2**64 - 1)], dtype="<u8").view(np.uint8)
        frame[0, :16] = stamp
        now = time.time_ns()
        for publisher in publishers:
            msg = Image()
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, 10**9)
            msg.height, msg.width, msg.encoding, msg.step = args.height, args.width, "mono8", args.width
            msg.data = frame.tobytes()
            try:
                publisher.publish(msg)
            except Exception:  # SIGTERM shut rclpy's context down: the run is over
                if rclpy.ok():
                    raise
        k += 1
        time.sleep(max(0.0, start + k * period - time.monotonic()))
    print(json.dumps({"publisher_cpu_s": time.process_time() - cpu0, "frames": k}), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
