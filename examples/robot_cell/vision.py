"""The image processing node of the robotic cell (the paper's Fig. 1).

It subscribes to the stereo pairs that the acquisition service publishes on
``cell/pairs`` (answers to the robot's request events), finds the chessboard in
both images with OpenCV, and publishes the mean horizontal disparity of the
matched corners on its own PUB socket under ``cell/results``:

    {"request_id": 7, "t_request": ..., "disparity_px": 24.0,
     "frames": {"left": 1234, "right": 1234}, "t_received": ..., "t_done": ...}

An error answer from the service (or a pair without a visible board) becomes a
result with an ``error`` field, so the robot is never left waiting. An answer
to a ``time`` event on ``cell/pairs`` is echoed as ``{"request_id", "ping":
true}``: the robot uses it to check the whole chain before it starts.

    python vision.py --pub tcp://127.0.0.1:5556 --events tcp://127.0.0.1:5557 \\
                     --results tcp://127.0.0.1:5558

stdout carries exactly one line, ``ready``, once the pair subscription is live
(checked with ``fxis_shm.client.pubsub.handshake``); everything else goes to stderr.
SIGTERM or SIGINT stops it with exit code 0.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time

import cv2
import numpy as np
import zmq

from fxis_shm import EventPublisher, FxisError, Message, RequestTimeout, Subscriber, handshake

PAIRS_TOPIC = "cell/pairs"
RESULTS_TOPIC = "cell/results"
# Subscribed to right after PAIRS_TOPIC on the same socket: subscriptions reach
# the service in order, so an answer on it proves the pair subscription is live.
PROBE_TOPIC = "cell/vision-probe"
DEFAULT_RESULTS = "tcp://127.0.0.1:5558"
BOARD = (9, 6)  # inner corners per row and per column, as the synthetic camera draws them
_SUBPIX = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)


class Stop(Exception):
    """Raised by the SIGTERM/SIGINT handler."""


def _on_signal(signum, frame):
    for sig in (signal.SIGTERM, signal.SIGINT):  # one stop is enough; do not interrupt the clean-up
        signal.signal(sig, signal.SIG_IGN)
    raise Stop(signal.Signals(signum).name)


def log(*parts) -> None:
    print("vision:", *parts, file=sys.stderr, flush=True)


# ---- the image processing ----


def find_corners(image: np.ndarray) -> np.ndarray | None:
    """The board's inner corners as a (rows, cols, 2) array of (x, y), ordered
    top-left first whichever way round OpenCV found them; None if no board."""
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, BOARD, flags=flags)
    if not found:
        return None
    corners = cv2.cornerSubPix(gray, corners.reshape(-1, 1, 2).astype(np.float32), (5, 5), (-1, -1), _SUBPIX)
    grid = corners.reshape(BOARD[1], BOARD[0], 2)
    if grid[0, 0, 0] > grid[0, -1, 0]:  # found right to left
        grid = grid[:, ::-1]
    if grid[0, 0, 1] > grid[-1, 0, 1]:  # found bottom to top
        grid = grid[::-1]
    return grid


def disparity(left: np.ndarray, right: np.ndarray) -> float:
    """Mean horizontal disparity (x in left minus x in right) of the matched corners, px."""
    corners = {}
    for side, image in (("left", left), ("right", right)):
        corners[side] = find_corners(image)
        if corners[side] is None:
            raise ValueError(f"no chessboard found in the {side} image")
    return float(np.mean(corners["left"][..., 0] - corners["right"][..., 0]))


def process(message: Message, left: str, right: str) -> dict | None:
    """The result to publish for one message on the pairs topic (None: not ours)."""
    if message.topic != PAIRS_TOPIC:
        return None  # a late answer to one of our handshake probes
    t_received = time.monotonic_ns()
    header = message.header
    result = {"request_id": header.get("id"), "t_request": header.get("t_request"), "t_received": t_received}
    if not message.ok:
        err = header.get("error") or {}
        result["error"] = f"service: {err.get('code', 'UNKNOWN')}: {err.get('message', '')}"
    elif header.get("op") == "time":
        result["ping"] = True  # the robot checks the chain robot -> service -> us -> robot
    else:
        try:
            pair = message.tuple
            missing = [c for c in (left, right) if c not in pair]
            if missing:
                raise ValueError(f"the pair lacks camera(s) {missing}; it has {sorted(pair)}")
            result["frames"] = {c: pair[c].frame_id for c in (left, right)}
            result["disparity_px"] = disparity(pair[left].image, pair[right].image)
        except (FxisError, ValueError, cv2.error) as exc:
            result["error"] = f"vision: {exc}"
    result["t_done"] = time.monotonic_ns()
    return result


# ---- the node ----


def serve(args, out) -> None:
    ctx = zmq.Context()
    parent = os.getppid()
    try:
        results = ctx.socket(zmq.PUB)
        results.setsockopt(zmq.LINGER, 500)  # let the last results go out on exit
        results.bind(args.results)
        try:
            with Subscriber(args.pub, context=ctx) as pairs:
                pairs.topic(PAIRS_TOPIC)
                pairs.topic(PROBE_TOPIC)
                with EventPublisher(args.events, context=ctx) as probes:
                    handshake(probes, pairs, PROBE_TOPIC, timeout=args.ready_timeout)
                log(f"subscribed to {PAIRS_TOPIC!r} on {args.pub}; publishing {RESULTS_TOPIC!r} on {args.results}")
                print("ready", file=out, flush=True)
                while True:
                    if args.exit_with_parent and os.getppid() != parent:
                        log("parent process gone; stopping")
                        return
                    try:
                        message = pairs.receive(timeout=0.5)
                    except RequestTimeout:
                        continue
                    except FxisError as exc:  # a malformed message: say so, keep serving
                        log(f"skipped a message: {exc}")
                        continue
                    result = process(message, args.left, args.right)
                    if result is None:
                        continue
                    results.send_multipart([RESULTS_TOPIC.encode(), json.dumps(result).encode()])
                    if "error" in result:
                        log(f"request {result['request_id']}: {result['error']}")
                    elif args.verbose and "disparity_px" in result:
                        log(
                            f"request {result['request_id']}: frames {result['frames']}, "
                            f"disparity {result['disparity_px']:.3f} px in "
                            f"{(result['t_done'] - result['t_received']) / 1e6:.1f} ms"
                        )
        finally:
            results.close()
    finally:
        ctx.term()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument(
        "--pub", default="tcp://127.0.0.1:5556", help="the service's publish endpoint, where the pairs come from"
    )
    p.add_argument(
        "--events",
        default="tcp://127.0.0.1:5557",
        help="the service's events endpoint (used only for the start-up handshake)",
    )
    p.add_argument(
        "--results",
        default=DEFAULT_RESULTS,
        help=f"endpoint this node binds and publishes results on (default {DEFAULT_RESULTS})",
    )
    p.add_argument("--left", default="left", help="name of the left camera")
    p.add_argument("--right", default="right", help="name of the right camera")
    p.add_argument("--ready-timeout", type=float, default=10.0, help="seconds to wait for the service at start-up")
    p.add_argument(
        "--exit-with-parent", action="store_true", help="stop when the process that started this one goes away"
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log every result on stderr")
    args = p.parse_args(argv)
    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)
    try:
        serve(args, sys.stdout)
    except Stop as stop:
        log(f"stopped by {stop}")
    except RequestTimeout as exc:
        log(f"start-up failed: {exc}")
        return 1
    except zmq.ZMQError as exc:
        log(f"ZeroMQ error (is {args.results} free?): {exc}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
