"""rosbag2 folders with MCAP storage, written and read with the ``mcap`` and
``mcap-ros2-support`` libraries (the optional extra ``record``).

A bag is a folder holding ``metadata.yaml`` (what ``ros2 bag info`` and the ``rosbags``
library read first) and one ``.mcap`` file (its own summary: schemas, channels,
statistics, and a metadata record ``fxis`` naming the clock the stamps are in and how the
bag ended, written when it is closed; ``fxis.begun``, written first, says what was known
at the start, so that a bag whose writer was killed still names its clock). The
writer keeps the counts ``metadata.yaml`` needs and writes it when the bag is closed,
so a bag is valid as soon as ``close`` returns (also after Ctrl-C, and when the disk fills:
``BagWriter``). A bag whose writer was killed is read as far as it is complete
(``BagReader``) and repaired by fxis_shm.formats.bagrecover (``fxis record --recover``);
the MCAP records themselves are handled by fxis_shm.formats.mcaprecover.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

from fxis_shm.errors import ConfigError, DiskFull, FxisError
from fxis_shm.formats import rosmsgs

METADATA_FILE = "metadata.yaml"
RESERVE_FILE = ".fxis-reserve"  # space kept to close the bag on a full disk (BagWriter)
RESERVE_BASE = 1 << 20  # beyond twice the summary: metadata.yaml, the message indexes of a cut chunk
RESERVE_STEP = 1 << 18  # grown by at least this much at a time
CHUNK_SECONDS = 1.0  # a chunk is written at the latest this long after it was begun
DISK_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
RECORD, BEGUN_RECORD = "fxis", "fxis.begun"  # the MCAP metadata records (the module's docstring)
ROSBAG2_VERSION = 8  # custom_data (6), type_description_hash (7), ros_distro (8)
EXTRA_HINT = "pip install 'fxis-shm[record]' (or `make setup`)"


def require_mcap(what: str):
    """The mcap modules, or ConfigError naming the extra that brings them."""
    try:
        import mcap.reader
        import mcap.writer
        import mcap_ros2.decoder
        import mcap_ros2.writer
    except ImportError as exc:
        raise ConfigError(
            f"{what} needs the optional extra 'record' (the mcap and mcap-ros2-support libraries; {exc}): {EXTRA_HINT}"
        ) from None
    return mcap, mcap_ros2


@dataclass
class _TopicCount:
    msgtype: str
    count: int = 0


@dataclass
class BagWriter:
    """``BagWriter(folder, custom_data)``; ``write(topic, msgtype, message, log_time)``; ``close()``.

    **A full disk** does not cost the bag. Readers start from the MCAP footer and summary
    (a metadata.yaml written early would not help), so the writer keeps room to write them:
    a reserve, a preallocated file (``.fxis-reserve`` in the bag) of 1 MiB plus twice what
    the summary would take so far, grown as the recording goes (the summary takes about 90
    bytes a chunk: 13 MB for an hour of two 1360x1024 cameras at 20 fps). Every write reaches
    the file whole or fails, and each is indexed as it lands
    (fxis_shm.formats.mcaprecover.McapIndex), so the writer knows where its last complete
    record ends without reading anything back. When a write, or growing the reserve, fails
    for want of space (ENOSPC, EDQUOT, EFBIG), the writer cuts the file after that record,
    deletes the reserve, writes the summary and footer there, then metadata.yaml, and
    raises ``DiskFull`` naming what the bag kept: every message counted is in the bag; those
    of the chunk that did not fit are not. Only if something else takes the freed space
    first does the bag stay unfinished (``DiskFull.valid`` False; ``fxis record --recover``
    finishes it once there is room).

    **A kill or a power cut** leaves the records written up to then (the writer holds at
    most one chunk in memory: 1 MiB, or ``CHUNK_SECONDS`` of messages) and no end;
    fxis_shm.formats.bagrecover (``fxis record --recover``) finishes such a bag, and
    ``BagReader`` plays it as it is. ``custom_data`` is written first as the ``fxis.begun``
    metadata record, so that it survives too, and as it is at the end as ``fxis`` (once,
    complete) when the bag is closed, also on a full disk.

    ``file_stem``: the .mcap file is ``STEM_0.mcap`` (default: the folder's name, as rosbag2
    names it; a bag written under a temporary name passes its final one).
    """

    folder: str
    custom_data: dict = field(default_factory=dict)
    ros_distro: str = "jazzy"  # the message definitions are those of every ROS 2 release
    file_stem: str = ""

    def __post_init__(self):
        mcap, mcap_ros2 = require_mcap("recording")
        from fxis_shm.formats.mcaprecover import IndexedFile

        if os.path.exists(self.folder) and (not os.path.isdir(self.folder) or os.listdir(self.folder)):
            raise ConfigError(
                f"--out {self.folder}: exists and is not an empty folder (a bag is a new folder; choose another name)"
            )
        made = not os.path.exists(self.folder)
        os.makedirs(self.folder, exist_ok=True)
        self.file_name = (self.file_stem or os.path.basename(os.path.normpath(self.folder))) + "_0.mcap"
        self.path = os.path.join(self.folder, self.file_name)
        self._reserve = _Reserve(os.path.join(self.folder, RESERVE_FILE))
        self._schemas: dict = {}
        self.topics: dict[str, _TopicCount] = {}
        self.first_time: int | None = None
        self.last_time: int | None = None
        self.bytes_written = 0
        self.closed = False
        try:
            self._reserve.grow(RESERVE_BASE + RESERVE_STEP)
            self._file = IndexedFile(self.path)
            # No chunk compression: images are large and raw ones barely compress; the
            # recorder's CPU is better spent keeping up (JPEG is compressed already).
            self._writer = mcap_ros2.writer.Writer(self._file, compression=mcap.writer.CompressionType.NONE)
            self._writer.add_metadata(BEGUN_RECORD, self._custom_strings())  # first, so a cut-off bag keeps it
        except OSError as exc:
            if exc.errno not in DISK_FULL:
                raise
            self._reserve.remove()
            with contextlib.suppress(OSError):
                os.remove(self.path)
            if made:
                with contextlib.suppress(OSError):
                    os.rmdir(self.folder)
            raise DiskFull(
                f"{self.folder}: {exc.strerror}: no room to start a bag (it keeps {RESERVE_BASE >> 20} MiB "
                "free to close it properly when the disk fills)",
                folder=self.folder,
                reason=exc.strerror,
                valid=False,
            ) from None
        self._chunks, self._chunk_since = 0, time.monotonic()

    def write(self, topic: str, msgtype: str, message: dict, log_time: int, size: int = 0) -> None:
        """Add one message; ``size`` (its payload bytes) is added to ``bytes_written``.
        ``DiskFull`` if the disk is full: the bag is then closed with what fitted."""
        if self.closed:
            raise FxisError(f"{self.folder}: the bag is closed")
        schema = self._schemas.get(msgtype)
        counted = self.topics.get(topic) or _TopicCount(msgtype)
        try:
            if schema is None:
                schema = self._schemas[msgtype] = self._writer.register_msgdef(msgtype, rosmsgs.DEFINITIONS[msgtype])
            self._writer.write_message(
                topic, schema, message, log_time=log_time, publish_time=log_time, sequence=counted.count
            )
            self._keep_up()
        except OSError as exc:
            if exc.errno not in DISK_FULL:
                raise
            self._close_what_fits(exc)
        self.topics[topic] = counted
        counted.count += 1
        self.bytes_written += size
        self.first_time = log_time if self.first_time is None else min(self.first_time, log_time)
        self.last_time = log_time if self.last_time is None else max(self.last_time, log_time)

    def _keep_up(self) -> None:
        """Grow the reserve with the summary; end a chunk open for over CHUNK_SECONDS."""
        index = self._file.index
        if RESERVE_BASE + 2 * index.summary_bytes > self._reserve.size:
            self._reserve.grow(RESERVE_BASE + 2 * index.summary_bytes + RESERVE_STEP)
        now = time.monotonic()
        if len(index.chunk_indexes) != self._chunks:
            self._chunks, self._chunk_since = len(index.chunk_indexes), now
        elif now - self._chunk_since > CHUNK_SECONDS:  # what a kill costs is bounded in time too
            flush = getattr(getattr(self._writer, "_writer", None), "flush", None)  # (mcap >= 1.2)
            if flush is not None:
                flush()

    def close(self) -> None:
        """Finish the MCAP file (summary, index) and write metadata.yaml."""
        if self.closed:
            return
        self.closed = True
        try:
            self._reserve.remove()
            self._writer.add_metadata(RECORD, self._custom_strings())
            self._writer.finish()
            self._file.close()
            write_metadata(self.folder, self.metadata())
        except OSError as exc:
            if exc.errno not in DISK_FULL:
                raise
            self._close_what_fits(exc)

    def _close_what_fits(self, exc: OSError):
        """Close the file after its last complete record, write metadata.yaml, raise DiskFull."""
        from fxis_shm.formats.mcaprecover import closing

        self.closed = True
        self._reserve.remove()
        index = self._file.index
        failed = None
        try:
            if not self.custom_data.get("ended"):  # (how the bag ended, if its writer did not say)
                self.custom_data["ended"] = f"the disk was full ({exc.strerror}): closed with what fitted"
            last_word = {} if RECORD in index.metadata else {RECORD: self._custom_strings()}
            self._file.close_at(index.end, closing(index, last_word))
            self.topics = {t: _TopicCount(msgtype, n) for t, (msgtype, n) in index.topics().items()}
            self.first_time, self.last_time = (
                (index.start_time, index.end_time) if index.message_count else (None, None)
            )
            write_metadata(self.folder, self.metadata())
        except OSError as again:
            failed = again
        kept = {t: c.count for t, c in self.topics.items()} if failed is None else {}
        seconds = (index.end_time - index.start_time) / 1e9
        size = os.path.getsize(self.path) if os.path.exists(self.path) else 0
        what = ", ".join(f"{t} {n}" for t, n in kept.items())
        said = (
            f"the bag was closed with what fitted: {sum(kept.values())} messages ({what}), "
            f"{seconds:.1f} s, {size / 1e6:.1f} MB"
            if failed is None
            else f"the bag could not be closed ({failed.strerror}): make room, then fxis record --recover {self.folder}"
        )
        raise DiskFull(
            f"{self.folder}: {exc.strerror}: {said}",
            folder=self.folder,
            reason=exc.strerror,
            kept=kept,
            seconds=seconds,
            file_bytes=size,
            valid=failed is None,
        ) from None

    def _custom_strings(self) -> dict[str, str]:
        return {k: str(v) for k, v in self.custom_data.items()}

    def metadata(self) -> dict:
        counts = {topic: (t.msgtype, t.count) for topic, t in self.topics.items()}
        return bag_info(
            self.file_name, counts, self.first_time, self.last_time, self._custom_strings(), self.ros_distro
        )


class _Reserve:
    """Disk space kept for closing a bag: a preallocated file, deleted to free its space."""

    def __init__(self, path: str):
        self.path, self.size = path, 0

    def grow(self, size: int) -> None:
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT, 0o600)
        try:
            os.posix_fallocate(fd, 0, size)
        finally:
            os.close(fd)
        self.size = size

    def remove(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            os.remove(self.path)
        self.size = 0


def bag_info(
    file_name: str,
    topics: dict[str, tuple[str, int]],
    first: int | None,
    last: int | None,
    custom_data: dict[str, str],
    ros_distro: str = "jazzy",
) -> dict:
    """metadata.yaml's ``rosbag2_bagfile_information`` of a one-file bag: ``topics`` maps
    each topic to (message type, count); ``first`` and ``last`` are log times."""
    start = first or 0
    duration = (last - start) if last is not None else 0
    total = sum(count for _, count in topics.values())
    return {
        "version": ROSBAG2_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": total,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": topic,
                    "type": msgtype,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": "",
                    "type_description_hash": "",
                },
                "message_count": count,
            }
            for topic, (msgtype, count) in topics.items()
        ],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [
            {
                "path": file_name,
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": duration},
                "message_count": total,
            }
        ],
        "custom_data": custom_data,
        "ros_distro": ros_distro,
    }


def write_metadata(folder: str, info: dict) -> None:
    """metadata.yaml, written whole or not at all (a new file renamed over the old one)."""
    path = os.path.join(folder, METADATA_FILE)
    with open(path + ".new", "w") as f:
        f.write(to_yaml({"rosbag2_bagfile_information": info}))
    os.replace(path + ".new", path)


def to_yaml(value, indent: int = 0) -> str:
    """Block-style YAML of nested dicts, lists and scalars (scalars as JSON, which YAML reads)."""
    pad = " " * indent
    if isinstance(value, dict):
        if not value:
            return "{}\n"
        lines = []
        for key, item in value.items():
            if isinstance(item, (dict, list)) and item:
                lines.append(f"{pad}{key}:\n{to_yaml(item, indent + 2)}")
            else:
                lines.append(f"{pad}{key}: {to_yaml(item).strip()}\n")
        return "".join(lines)
    if isinstance(value, list):
        if not value:
            return "[]\n"
        lines = []
        for item in value:
            text = to_yaml(item, indent + 2).lstrip() if isinstance(item, (dict, list)) else to_yaml(item)
            lines.append(f"{pad}- {text}")
        return "".join(lines)
    return json.dumps(value) + "\n"


# ---- reading (the ``bag`` camera) ---------------------------------------------------------------


def mcap_file(path: str) -> str:
    """The .mcap file of a bag folder (named in its metadata.yaml), or ``path`` if it is one."""
    if os.path.isfile(path):
        return path
    if not os.path.isdir(path):
        raise ConfigError(f"no bag at {path!r} (expected a rosbag2 folder or an .mcap file)")
    names = sorted(n for n in os.listdir(path) if n.endswith(".mcap"))
    if not names:
        raise ConfigError(f"the folder {path!r} holds no .mcap file (is it a bag recorded with MCAP storage?)")
    if len(names) > 1:
        raise ConfigError(
            f"the bag {path!r} is split into {len(names)} files; replay reads one: give path= one of {', '.join(names)}"
        )
    return os.path.join(path, names[0])


class BagReader:
    """One bag's topics, time span and decoded messages. A file without its summary (a
    recording killed, or cut off by a copy) is read as far as its records are complete,
    without changing it: ``repair`` then says what was wrong (``damage`` in words)."""

    def __init__(self, path: str):
        mcap, mcap_ros2 = require_mcap("the bag camera")
        self.path = mcap_file(path)
        self._make_reader = mcap.reader.make_reader
        self._decoders = [mcap_ros2.decoder.DecoderFactory()]
        self._open = lambda: open(self.path, "rb")
        self.repair = None
        summary = self._summary()
        if summary is None:
            from fxis_shm.formats.mcaprecover import examine

            self.repair = examine(self.path)  # ConfigError if it is no MCAP file at all
            self._open = self.repair.open
            summary = self._summary()
        if summary is None:
            raise ConfigError(f"{self.path!r} is not a readable MCAP file, not even record by record")
        schemas = summary.schemas
        self.topics = {
            ch.topic: schemas[ch.schema_id].name if ch.schema_id in schemas else "" for ch in summary.channels.values()
        }
        self.counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
        self.start_time = summary.statistics.message_start_time
        self.end_time = summary.statistics.message_end_time
        self.metadata = self._metadata()

    def _summary(self):
        with self._open() as f:
            try:
                summary = self._make_reader(f).get_summary()
            except Exception:  # the mcap library's errors have no common base
                return None
        return summary if summary is not None and summary.statistics is not None else None

    def damage(self, topic: str, detail: bool = False) -> str:
        """What was wrong with the file and how much of ``topic`` plays ("" if nothing was)."""
        if self.repair is None:
            return ""
        where = f"{self.path}: " if detail else ""
        return (
            f"{where}no summary (recording cut off?): plays {self.counts.get(topic, 0)} of the file's "
            f"{self.repair.index.message_count} complete messages; {self.repair.describe(detail)}"
        )

    def _metadata(self) -> dict:
        with self._open() as f:
            return {m.name: dict(m.metadata) for m in self._make_reader(f).iter_metadata()}

    def messages(self, topic: str, start_time: int | None = None) -> Iterator[tuple[int, object]]:
        """(log_time, decoded message) of the messages of ``topic`` logged at or after
        ``start_time`` (default all), in log-time order."""
        with self._open() as f:
            reader = self._make_reader(f, decoder_factories=self._decoders)
            for _, _, message, decoded in reader.iter_decoded_messages(topics=[topic], start_time=start_time):
                yield message.log_time, decoded
