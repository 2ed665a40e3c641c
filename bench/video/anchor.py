"""The anchor: CPU a frame of our H.264 encoder against the `ffmpeg` command line encoding the
same frames with the same settings (issue 35's target: ours at most 1.1x ffmpeg's).

Makes --seconds of the realistic scene (bench/video/scene.py; 1360x1024 mono8 at 30 fps),
writes them to a raw file in a temp folder, then --repeats times, alternating:
  ours     every frame through the encoder `fxis record --codec h264` chooses with its defaults
           (bench/video/product.py: VideoPlan, StreamEncoder; numpy gray -> yuv420p -> libx264 in
           PyAV's bundled FFmpeg), in this process;
  ffmpeg   the `ffmpeg` CLI reading the raw file: libx264 with the options StreamEncoder gives
           (the same crf, preset, x264-params, forced IDR keyframes every 2 s of time, no
           B-frames, gop, PyAV's threading: thread_type slice, threads auto), output Annex B.
CPU time is user + system of every thread (getrusage: this process for ours, the child for
ffmpeg), not wall time, since the machine is shared; the load average is printed beside it.
The two use different builds of libx264 (PyAV's wheel and the system's FFmpeg): both versions
are printed.

Needs the `ffmpeg` program (Debian: `apt-get install ffmpeg`; scripts/install-system-packages.sh
installs it); without it, says so, prints ours alone and exits 1. Writes video_anchor.json into
--out. Exit status 0; 1 if ffmpeg is missing or fails; 2 on bad flags.
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile

if not __package__:  # run as a script (python bench/video/anchor.py): the project root on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from bench.shared import common
from bench.video import product
from bench.video.scene import add_scene_args, parse
from fxis_shm.formats import videoencoder

CODEC = "h264"
TARGET_RATIO = 1.1


def parser():
    p = common.parser_for(__file__, __doc__)
    p.add_argument("--repeats", type=common.positive_int, default=2, help="runs of each, alternating")
    add_scene_args(p)
    common.add_output_args(p, seed_help="seed of the scene's sensor noise")
    return p


def ffmpeg_command(plan, raw_path: str, width: int, height: int, fps: float, out_path: str) -> list[str]:
    """The ffmpeg CLI doing what StreamEncoder does with ``plan`` (libx264 only)."""
    options = videoencoder.encoder_options(plan.choice, plan.crf, plan.preset, 1 << 20)
    assert plan.choice.encoder == "libx264", plan.choice
    return [
        "ffmpeg", "-hide_banner", "-nostdin", "-loglevel", "error", "-y",
        "-f", "rawvideo", "-pix_fmt", "gray", "-s", f"{width}x{height}", "-framerate", f"{fps:g}", "-i", raw_path,
        "-c:v", "libx264", "-pix_fmt", "yuv420p",
        "-preset", options["preset"], "-crf", options["crf"], "-x264-params", options["x264-params"],
        "-forced-idr", options["forced-idr"], "-force_key_frames", f"expr:gte(t,n_forced*{plan.gop_s:g})",
        "-g", str(1 << 20), "-bf", "0", "-threads", "0", "-thread_type", "slice",
        "-f", "h264", out_path,
    ]  # fmt: skip


def run_ffmpeg(command: list[str]) -> tuple[float, int]:
    """CPU seconds (user + system) the ffmpeg child took, and its output's size."""
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace").strip() if proc.stderr else ""
    if proc.stderr:
        proc.stderr.close()
    if proc.returncode != 0:
        raise RuntimeError(f"ffmpeg failed (exit {proc.returncode}): {err}")
    return usage.ru_utime + usage.ru_stime, os.path.getsize(command[-1])


def versions() -> dict:
    import av

    ffmpeg = shutil.which("ffmpeg")
    line = (
        subprocess.run([ffmpeg, "-version"], capture_output=True, text=True).stdout.splitlines()[0] if ffmpeg else None
    )
    return {"pyav": av.__version__, "pyav_libavcodec": av.library_versions["libavcodec"], "ffmpeg_cli": line}


def main(argv: list[str] | None = None) -> int:
    parsed = parse(parser(), argv)
    if isinstance(parsed, int):
        return parsed
    args, out, scene, n = parsed
    print(f"scene: {scene.describe()}; {n} frames", file=sys.stderr)
    frames = scene.frames(n)
    plan = product.plan_for(CODEC, frames, args.fps)
    ffmpeg = shutil.which("ffmpeg")
    if ffmpeg is None:
        print("anchor.py: no `ffmpeg` program on PATH: apt-get install ffmpeg (scripts/install-system-packages.sh)",
              file=sys.stderr)  # fmt: skip
    runs: dict[str, list[float]] = {"ours": [], "ffmpeg": []}
    sizes: dict[str, int] = {}
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="video_anchor.") as scratch:
        raw_path = os.path.join(scratch, "scene.gray")
        with open(raw_path, "wb") as f:
            for frame in frames:
                f.write(frame.tobytes())
        command = ffmpeg_command(plan, raw_path, args.width, args.height, args.fps, os.path.join(scratch, "out.h264"))
        for i in range(args.repeats):
            print(f"run {i + 1} of {args.repeats}: ours ...", file=sys.stderr, flush=True)
            done = product.encode(CODEC, frames, args.fps)
            runs["ours"].append(done.cpu_s / n * 1e3)
            sizes["ours"] = sum(len(p) for p in done.packets)
            if ffmpeg is not None:
                print(f"run {i + 1} of {args.repeats}: ffmpeg ...", file=sys.stderr, flush=True)
                try:
                    cpu, sizes["ffmpeg"] = run_ffmpeg(command)
                except RuntimeError as exc:
                    print(f"anchor.py: {exc}", file=sys.stderr)
                    return common.EXIT_FAILED
                runs["ffmpeg"].append(cpu / n * 1e3)
    load_after = os.getloadavg()
    rows = [
        [who, *(f"{v:.2f}" for v in ms), f"{statistics.median(ms):.2f}", f"{sizes[who] / n / 1e3:.1f}"]
        for who, ms in runs.items()
        if ms
    ]
    header = ["encoder", *(f"run {i + 1}" for i in range(args.repeats)), "median", "kB/frame"]
    title = (
        f"CPU ms a frame (user + system), {n} frames of {args.width}x{args.height} mono8, {plan.describe()}; "
        f"load average {load_before[0]:.2f} before, {load_after[0]:.2f} after ({os.cpu_count()} CPUs)"
    )
    print(common.table(header, rows, title=title))
    ratio = statistics.median(runs["ours"]) / statistics.median(runs["ffmpeg"]) if runs["ffmpeg"] else None
    if ratio is not None:
        print(f"ours / ffmpeg: {ratio:.2f}x (target <= {TARGET_RATIO}x): {common.verdict(ratio <= TARGET_RATIO)}")
    print("ffmpeg command (the raw file is the scene's frames):\n  " + " ".join(command))
    found = versions()
    print(f"PyAV {found['pyav']} (libavcodec {'.'.join(map(str, found['pyav_libavcodec']))}); {found['ffmpeg_cli']}")
    print(f"scene: {scene.describe()}")
    print(common.code_line(common.code_version()))
    kept = {"settings": vars(args), "scene": scene.describe(), "plan": plan.describe(), "ffmpeg_command": command}
    kept.update(cpu_ms_per_frame=runs, bytes=sizes, ratio=ratio, versions=found, host=common.host_info())
    kept["load_average"] = {"before": load_before, "after": load_after}
    common.write_json(os.path.join(out, "video_anchor.json"), kept)
    return common.EXIT_OK if ratio is not None else common.EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
