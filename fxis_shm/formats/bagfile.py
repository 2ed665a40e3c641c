"""rosbag2 folders with MCAP storage, written and read with the ``mcap`` and
``mcap-ros2-support`` libraries (the optional extra ``record``).

A bag is a folder holding ``metadata.yaml`` (what ``ros2 bag info`` and the ``rosbags``
library read first) and one ``.mcap`` file (its own summary: schemas, channels,
statistics, and a metadata record ``fxis`` naming the clock the stamps are in). The
writer keeps the counts ``metadata.yaml`` needs and writes it when the bag is closed,
so a bag is valid as soon as ``close`` returns (also after Ctrl-C).
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field

from fxis_shm.errors import ConfigError
from fxis_shm.formats import rosmsgs

METADATA_FILE = "metadata.yaml"
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
    """``BagWriter(folder, custom_data)``; ``write(topic, msgtype, message, log_time)``; ``close()``."""

    folder: str
    custom_data: dict = field(default_factory=dict)
    ros_distro: str = "jazzy"  # the message definitions are those of every ROS 2 release

    def __post_init__(self):
        mcap, mcap_ros2 = require_mcap("recording")
        if os.path.exists(self.folder) and (not os.path.isdir(self.folder) or os.listdir(self.folder)):
            raise ConfigError(
                f"--out {self.folder}: exists and is not an empty folder (a bag is a new folder; choose another name)"
            )
        os.makedirs(self.folder, exist_ok=True)
        self.file_name = os.path.basename(os.path.normpath(self.folder)) + "_0.mcap"
        self._stream = open(os.path.join(self.folder, self.file_name), "wb")
        # No chunk compression: images are large and raw ones barely compress; the
        # recorder's CPU is better spent keeping up (JPEG is compressed already).
        self._writer = mcap_ros2.writer.Writer(self._stream, compression=mcap.writer.CompressionType.NONE)
        self._schemas: dict = {}
        self.topics: dict[str, _TopicCount] = {}
        self.first_time: int | None = None
        self.last_time: int | None = None
        self.bytes_written = 0
        self.closed = False

    def write(self, topic: str, msgtype: str, message: dict, log_time: int, size: int = 0) -> None:
        """Add one message; ``size`` (its payload bytes) is added to ``bytes_written``."""
        schema = self._schemas.get(msgtype)
        if schema is None:
            schema = self._schemas[msgtype] = self._writer.register_msgdef(msgtype, rosmsgs.DEFINITIONS[msgtype])
        counted = self.topics.setdefault(topic, _TopicCount(msgtype))
        self._writer.write_message(
            topic, schema, message, log_time=log_time, publish_time=log_time, sequence=counted.count
        )
        counted.count += 1
        self.bytes_written += size
        self.first_time = log_time if self.first_time is None else min(self.first_time, log_time)
        self.last_time = log_time if self.last_time is None else max(self.last_time, log_time)

    def close(self) -> None:
        """Finish the MCAP file (summary, index) and write metadata.yaml."""
        if self.closed:
            return
        self.closed = True
        self._writer.add_metadata("fxis", {k: str(v) for k, v in self.custom_data.items()})
        self._writer.finish()
        self._stream.close()
        with open(os.path.join(self.folder, METADATA_FILE), "w") as f:
            f.write(to_yaml({"rosbag2_bagfile_information": self.metadata()}))

    def metadata(self) -> dict:
        start = self.first_time or 0
        duration = (self.last_time - start) if self.last_time is not None else 0
        total = sum(t.count for t in self.topics.values())
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
                        "type": t.msgtype,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": "",
                        "type_description_hash": "",
                    },
                    "message_count": t.count,
                }
                for topic, t in self.topics.items()
            ],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.file_name],
            "files": [
                {
                    "path": self.file_name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": total,
                }
            ],
            "custom_data": {k: str(v) for k, v in self.custom_data.items()},
            "ros_distro": self.ros_distro,
        }


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
    """One bag's topics, time span and decoded messages."""

    def __init__(self, path: str):
        mcap, mcap_ros2 = require_mcap("the bag camera")
        self.path = mcap_file(path)
        self._make_reader = mcap.reader.make_reader
        self._decoders = [mcap_ros2.decoder.DecoderFactory()]
        with open(self.path, "rb") as f:
            try:
                summary = self._make_reader(f).get_summary()
            except Exception as exc:  # the mcap library's errors have no common base
                raise ConfigError(f"{self.path!r} is not a readable MCAP file: {exc}") from None
        if summary is None or summary.statistics is None:
            raise ConfigError(f"{self.path!r} has no summary (was its recording cut off?)")
        schemas = summary.schemas
        self.topics = {
            ch.topic: schemas[ch.schema_id].name if ch.schema_id in schemas else "" for ch in summary.channels.values()
        }
        self.counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
        self.start_time = summary.statistics.message_start_time
        self.end_time = summary.statistics.message_end_time
        self.metadata = self._metadata()

    def _metadata(self) -> dict:
        with open(self.path, "rb") as f:
            return {m.name: dict(m.metadata) for m in self._make_reader(f).iter_metadata()}

    def messages(self, topic: str, start_time: int | None = None) -> Iterator[tuple[int, object]]:
        """(log_time, decoded message) of the messages of ``topic`` logged at or after
        ``start_time`` (default all), in log-time order."""
        with open(self.path, "rb") as f:
            reader = self._make_reader(f, decoder_factories=self._decoders)
            for _, _, message, decoded in reader.iter_decoded_messages(topics=[topic], start_time=start_time):
                yield message.log_time, decoded
