"""What the benchmarks in bench/ share: the service they measure, statistics,
tables, JSON and figure output, progress bars.

Not a public module: the benches import it as ``bench.shared.common``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import platform
import random
import subprocess
import sys
import time
from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from fxis_shm import Client, read_stamp
from fxis_shm.errors import FxisError, RequestTimeout
from fxis_shm.service.launch import ServiceProcess

BENCH = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_OUT = os.path.join(BENCH, "results")
NS_PER_MS = 1_000_000

EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


# ---- command line ----------------------------------------------------------------------------


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Shows defaults and keeps the description's line breaks."""


def add_service_args(p: argparse.ArgumentParser, endpoint_note: str = "") -> None:
    """--endpoint, --out, --timeout, --seed: the same meaning in every benchmark."""
    g = p.add_argument_group("service and output")
    g.add_argument(
        "--endpoint",
        metavar="URL",
        help="measure the service already running at this endpoint (e.g. "
        "tcp://127.0.0.1:5555, on this host) instead of launching one"
        + (f"; {endpoint_note}" if endpoint_note else ""),
    )
    add_output_args(g)


def add_output_args(
    g,
    out_help: str = "folder for the JSON and PNG files (created if missing; files are overwritten)",
    seed_help: str = "seed of the random sleeps",
) -> None:
    """--out, --timeout, --seed, into an argument group (or parser) ``g``."""
    g.add_argument("--out", default=DEFAULT_OUT, metavar="DIR", help=out_help)
    g.add_argument(
        "--timeout",
        type=positive_float,
        default=3.0,
        metavar="S",
        help="client timeout per request, seconds (no request can hang longer)",
    )
    g.add_argument(
        "--seed", type=int, default=None, help=f"{seed_help} (default: random; the seed used is saved in the JSON)"
    )


def add_pacing_args(
    g, each: str, count: int, warmup: int, sleep_max_ms: float, flag: str = "--requests", what: str = "request"
) -> None:
    """-n/--requests (``flag``), --warmup and --sleep-max-ms into ``g`` (a parser or a group): how
    many timed requests (``what``) each point (``each``) measures, how many unrecorded ones run
    first, and the random sleep U[0, this] before each timed one."""
    g.add_argument("-n", flag, type=positive_int, default=count, help=f"timed {what}s {each}")
    g.add_argument("--warmup", type=int, default=warmup, help=f"unrecorded {what}s {each} first")
    g.add_argument(
        "--sleep-max-ms",
        type=nonnegative_float,
        default=sleep_max_ms,
        help=f"each timed {what} follows a sleep drawn from U[0, this] ms",
    )


def parser_for(path: str, description: str | None) -> argparse.ArgumentParser:
    """A bench's command line, named as it is run from the project root (bench/FOLDER/NAME.py)."""
    prog = os.path.relpath(os.path.abspath(path), os.path.dirname(BENCH))
    return argparse.ArgumentParser(prog=prog, description=description, formatter_class=HelpFormatter)


def add_frame_size_args(p, width: int, height: int) -> None:
    """--width and --height of the frames (``p``: a parser or an argument group)."""
    p.add_argument("--width", type=positive_int, default=width, help="frame width (px)")
    p.add_argument("--height", type=positive_int, default=height, help="frame height (px)")


def parse_args_and_out(p: argparse.ArgumentParser, argv: list[str] | None):
    """As ``parse_args``, with the results folder (--out) made: (args, out), or the exit status."""
    args = parse_args(p, argv)
    return args if isinstance(args, int) else (args, ensure_dir(args.out))


def parse_args(p: argparse.ArgumentParser, argv: list[str] | None):
    """The parsed flags, with ``seed`` drawn if none was given; or the exit status
    of --help or of bad flags (argparse printed why), returned rather than raised."""
    try:
        args = p.parse_args(argv)
    except SystemExit as exc:
        return exc.code
    if getattr(args, "seed", 0) is None:
        args.seed = random.SystemRandom().randrange(2**32)
    return args


def usage_error(p: argparse.ArgumentParser, message: str) -> int:
    """What ``p.error`` prints, but returned as exit status 2 rather than raised."""
    p.print_usage(sys.stderr)
    print(f"{p.prog}: error: {message}", file=sys.stderr)
    return EXIT_USAGE


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {value}")
    return value


def nonnegative_float(text: str) -> float:
    value = float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def int_between(low: int, high: int):
    """An argparse type: an integer from ``low`` to ``high``, both included."""

    def parse(text: str) -> int:
        value = int(text)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be {low}..{high}, got {value}")
        return value

    return parse


def int_list(text: str) -> list[int]:
    """An argparse type: comma-separated integers >= 0."""
    values = [int(v) for v in text.split(",") if v.strip()]
    if not values or min(values) < 0:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers >= 0, got {text!r}")
    return values


def name_list(choices: tuple[str, ...]):
    """An argparse type: a comma-separated subset of ``choices``, in the order of ``choices``."""

    def parse(text: str) -> list[str]:
        names = [v.strip() for v in text.split(",") if v.strip()]
        unknown = [n for n in names if n not in choices]
        if unknown or not names:
            raise argparse.ArgumentTypeError(f"choose from {','.join(choices)}, got {text!r}")
        return [c for c in choices if c in names]

    return parse


def synthetic_camera_flags(
    names: Sequence[str],
    fps: float,
    width: int,
    height: int,
    phases_ms: Sequence[float] | None = None,
    jitter_ms: float = 0.0,
) -> list[str]:
    """``--camera`` flags of ``fxis run`` for synthetic mono8 cameras."""
    flags = []
    for j, name in enumerate(names):
        opts = [f"fps={fps:g}", f"width={width}", f"height={height}", "pixel_format=mono8"]
        if phases_ms is not None:
            opts.append(f"phase_ms={phases_ms[j]:g}")
        if jitter_ms:
            opts.append(f"jitter_ms={jitter_ms:g}")
        flags += ["--camera", f"{name}=synthetic:" + ",".join(opts)]
    return flags


# ---- the service -----------------------------------------------------------------------------


@contextlib.contextmanager
def service(
    endpoint: str | None, run_args: list[str], log_path: str, timeout: float, http: str = "off"
) -> Iterator[tuple[Client, dict]]:
    """A client of the service to measure, and facts about it.

    With ``endpoint`` None a service is launched with ``fxis run <run_args>`` (its log goes
    to ``log_path``; its dashboard at ``http``, HOST:PORT or off) and stopped on exit;
    otherwise the running service is used as is.
    """
    info = {"launched": endpoint is None, "run_args": run_args if endpoint is None else None}
    with contextlib.ExitStack() as stack:
        if endpoint is None:
            log = stack.enter_context(open(log_path, "wb"))
            svc = stack.enter_context(ServiceProcess(run_args, stderr=log, http=http))
            endpoint = svc.endpoint
            info["log"] = log_path
        info["endpoint"] = endpoint
        client = stack.enter_context(Client(endpoint, timeout=timeout))
        status = client.status()  # the service says where it publishes and takes events
        info["pub"], info["events"] = status.get("pub"), status.get("events")
        yield client, info


def wait_until_streaming(client: Client, min_frames: int = 3, timeout: float = 15.0) -> dict:
    """The service's status once every camera is alive and has stored ``min_frames``
    frames (so its period is measured); raises RuntimeError after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            status = client.status()
        except RequestTimeout:
            status = None
        if status is not None:
            cams = status["cameras"]
            if cams and all(c["alive"] and (c.get("frames_stored") or 0) >= min_frames for c in cams.values()):
                return status
        if time.monotonic() > deadline:
            raise RuntimeError(
                f"the service's cameras did not stream within {timeout:.0f} s: {status and status['cameras']}"
            )
        time.sleep(0.05)


def wait_for_http(url: str, timeout: float = 15.0) -> None:
    """Return once ``url`` answers 200 (a dashboard listening); RuntimeError after ``timeout`` s."""
    import urllib.error
    import urllib.request

    deadline = time.monotonic() + timeout
    while True:
        try:
            with urllib.request.urlopen(url, timeout=2) as answer:
                if answer.status == 200:
                    return
        except (urllib.error.URLError, OSError):
            pass
        if time.monotonic() > deadline:
            raise RuntimeError(f"{url} did not answer within {timeout:.0f} s")
        time.sleep(0.1)


def stamp_ok(frame, kind: str) -> bool | None:
    """Whether a synthetic frame's pixels carry the frame id of its metadata (None: not checkable)."""
    if kind != "synthetic":
        return None
    return read_stamp(frame.image) == frame.frame_id


def describe_error(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


# What a single failed request raises (service error replies, client timeouts)
REQUEST_ERRORS = (FxisError,)


def host_info() -> dict:
    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "platform": platform.platform(),
        "code": code_version(),
    }


def code_line(code: dict) -> str:
    """One line naming the measured code, for the printed report."""
    if not code["commit"]:
        return "code: not in a git checkout"
    modified = code["modified"] or []
    return f"code: commit {code['commit'][:10]}" + (
        f" with uncommitted changes to {', '.join(modified)}" if modified else " (clean)"
    )


def code_version() -> dict:
    """The git commit of the measured code and the files that differ from it (None outside git)."""
    repo = os.path.dirname(BENCH)

    def git(*args):
        try:
            done = subprocess.run(["git", "-C", repo, *args], capture_output=True, text=True, timeout=5, check=True)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout

    commit = git("rev-parse", "HEAD")
    changed = git("status", "--porcelain", "--untracked-files=no")
    return {
        "commit": commit.strip() if commit else None,
        "modified": [line[3:] for line in changed.splitlines()] if changed is not None else None,
    }


# ---- numbers ---------------------------------------------------------------------------------


def ms(ns) -> float:
    return ns / NS_PER_MS


def summary(values: Iterable[float]) -> dict:
    """n, min, mean, median, p99, max and std (sample, ddof=1) of ``values``; None if empty."""
    a = np.asarray(list(values), dtype=float)
    if a.size == 0:
        return {"n": 0, "min": None, "mean": None, "median": None, "p99": None, "max": None, "std": None}
    return {
        "n": int(a.size),
        "min": float(a.min()),
        "mean": float(a.mean()),
        "median": float(np.median(a)),
        "p99": float(np.percentile(a, 99)),
        "max": float(a.max()),
        "std": float(a.std(ddof=1)) if a.size > 1 else 0.0,
    }


def verdict(passed: bool | None) -> str:
    """A target's verdict as printed: PASS, FAIL, or n/a when it could not be measured."""
    return {True: "PASS", False: "FAIL", None: "n/a"}[passed]


def fmt(value, digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return str(value)
    return f"{value:.{digits}f}"


def table(
    header: Sequence[str],
    rows: Sequence[Sequence],
    title: str | None = None,
    digits: int = 2,
    separators: Sequence[int] = (),
) -> str:
    """A plain-text table: first column left-aligned, the others right-aligned;
    a ``|`` is drawn before every column index in ``separators``."""
    cells = [list(header)] + [[r[0]] + [fmt(v, digits) if not isinstance(v, str) else v for v in r[1:]] for r in rows]
    widths = [max(len(str(row[i])) for row in cells) for i in range(len(header))]

    def line(row):
        parts = []
        for i, (v, w) in enumerate(zip(row, widths)):
            if i in separators:
                parts.append("|")
            parts.append(str(v).ljust(w) if i == 0 else str(v).rjust(w))
        return "  ".join(parts).rstrip()

    out = [line(cells[0]), "-" * len(line(cells[0]))] + [line(r) for r in cells[1:]]
    if title:
        out.insert(0, title)
    return "\n".join(out)


# ---- files -----------------------------------------------------------------------------------


def ensure_dir(path: str) -> str:
    os.makedirs(path, exist_ok=True)
    return path


def run_record(benchmark: str, started: float, argv: Sequence[str] | None, args: argparse.Namespace) -> dict:
    """The head of every bench's JSON: which bench, when it started (``time.time()``), its command
    line (``argv`` as main got it; None: the process's) and its settings (the parsed arguments)."""
    return {
        "benchmark": benchmark,
        "started_unix": started,
        "argv": sys.argv[1:] if argv is None else list(argv),
        "settings": dict(vars(args)),
    }


def write_json(path: str, obj) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(obj, f, indent=1, default=_json_default)
        f.write("\n")
    os.replace(tmp, path)


def _json_default(obj):
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def progress(total: int, desc: str):
    """A progress bar on a terminal; elsewhere (CI logs, output to a file) one line when the
    stage starts and one when it ends, so logs stay readable."""
    if sys.stderr.isatty():
        from tqdm import tqdm

        return tqdm(total=total, desc=desc, file=sys.stderr, unit="req", dynamic_ncols=True, leave=False)
    return _StageLines(total, desc)


class _StageLines:
    """What ``progress`` gives when stderr is not a terminal: the bar's calls, two lines."""

    def __init__(self, total: int, desc: str):
        self.total, self.desc, self.done, self.started = total, desc, 0, time.monotonic()
        print(f"{desc}: {total} steps ...", file=sys.stderr, flush=True)

    def update(self, n: int = 1) -> None:
        self.done += n

    def close(self) -> None:
        print(
            f"{self.desc}: {self.done} of {self.total} done in {time.monotonic() - self.started:.1f} s",
            file=sys.stderr,
            flush=True,
        )

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def sleep_ms(duration_ms: float) -> None:
    if duration_ms > 0:
        time.sleep(duration_ms / 1000)


def sleep_late_ms(duration_ms: float) -> float:
    """Sleeps ``duration_ms``; how many ms late the sleep ended: the scheduler's delay in waking
    a process at that moment (tens of us on an idle machine, ms on a loaded one), which every
    wake-up a bench times includes."""
    began = time.monotonic_ns()
    sleep_ms(duration_ms)
    return max(0.0, (time.monotonic_ns() - began) / 1e6 - max(0.0, duration_ms))
