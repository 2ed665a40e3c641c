"""``fxis grab``'s files: one PNG per camera, each written whole (a temporary name renamed),
then ``tuple.json``; files of an earlier grab in the folder are never replaced (refused).
Ctrl-C or SIGTERM while they are written keeps the PNGs already there and writes a
``tuple.json`` that names them, says ``ended: interrupted by SIGINT`` and lists the frames
``not_saved``; exit 130 (exitcodes.INTERRUPTED)."""

from __future__ import annotations

import contextlib
import os

from fxis_shm.cli import exitcodes
from fxis_shm.cli.stopsignals import as_interrupts, interrupted
from fxis_shm.client.snapshot import interrupted_by
from fxis_shm.formats.tuplefiles import META_FILE, image_files, tuple_json


def save_tuple(folder: str, frames) -> int:
    """The tuple's files in ``folder``; the exit code, with a line on what was saved."""
    saved: list[str] = []
    ended = "complete"
    names = [f"{c}.png" for c in frames] + [META_FILE]
    there = [n for n in names if os.path.lexists(os.path.join(folder, n))]
    if there:  # an earlier grab's: never replaced
        exitcodes.say("grab", f"{folder} already holds {', '.join(there)}: choose another --out")
        return exitcodes.USAGE
    try:
        os.makedirs(folder, exist_ok=True)
        try:
            with as_interrupts():
                for camera, (name, data) in zip(frames, image_files(frames)):
                    write_whole(os.path.join(folder, name), data)
                    saved.append(camera)
        except KeyboardInterrupt as exc:
            ended = f"interrupted by {interrupted_by(exc)}"
        write_whole(os.path.join(folder, META_FILE), tuple_json(frames, saved, ended))
    except OSError as exc:
        if exc.errno in exitcodes.DISK_FULL:  # one line and code 4 (fxis_shm.cli.main); what was written stays
            raise
        where = exc.filename or folder
        exitcodes.say("grab", f"could not write {where}: {exc.strerror} (--out names a folder to write into)")
        return exitcodes.USAGE
    if ended != "complete":
        kept = ", ".join(f"{c}.png" for c in saved) or "no image"
        return interrupted("grab", f"{ended}: kept {kept} and {META_FILE} (naming them) in {folder}")
    print(f"saved {len(frames)} image(s) and {META_FILE} to {folder} (skew {frames.skew_ns / 1e6:.3f} ms)")
    return exitcodes.DONE


def write_whole(path: str, data: bytes) -> None:
    """``path`` holds ``data`` whole, or is not there: written under a name of its own, then renamed."""
    part = path + ".part"
    try:
        with open(part, "wb") as f:
            f.write(data)
        os.replace(part, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(part)  # this run's own, unfinished
        raise
