"""MCAP files read record by record, without their summary, and given one again: what
``ros2 bag reindex`` does for rosbag2, for the files ``fxis record`` writes and any other.

An MCAP file is its magic, a data section of records (opcode, length, body: schemas,
channels, chunks of messages each followed by its message indexes, metadata), a data end
record, a summary (schemas, channels, statistics, chunk and metadata indexes), a footer
pointing at the summary, and the magic again. Readers start from the footer. A writer
that stops without writing the end (kill -9, a power cut, a full disk) leaves every record
it wrote before, the last one perhaps torn, and nothing a reader can start from.

``McapIndex`` gathers what a summary needs from complete data records, as they are
written (``BagWriter`` feeds it every write, so a full disk can close the file without
reading it back) or read back (``examine``). ``closing`` turns it into the records that
make the file whole after its last complete record: the message indexes the last chunk
lacks, the data end, the summary, the footer. A torn last chunk (uncompressed, as fxis
writes them) is not lost whole: its complete messages become a chunk of their own.

``examine`` makes a ``Repair`` of a file: its first ``keep`` bytes as they are, then
``tail``. It is written in place (a full disk), into a new file (``fxis record
--recover``), or only read (``SplicedFile``: the ``bag`` camera plays a damaged bag
without changing it).
"""

from __future__ import annotations

import io
import os
import struct
import zlib
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass

from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.exceptions import McapError, UnsupportedCompressionError
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.stream_reader import get_chunk_data_stream

from fxis_shm.errors import ConfigError

MAGIC = b"\x89MCAP0\r\n"
_RECORD = struct.Struct("<BQ")  # opcode, body length
_CHUNK = struct.Struct("<QQQII")  # start time, end time, uncompressed size, crc, compression length
_MESSAGE = struct.Struct("<HIQ")  # channel id, sequence, log time
_U16, _U64 = struct.Struct("<H"), struct.Struct("<Q")
_CHUNK_INNER = {Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE}
_DATA = {op for op in Opcode if op not in (Opcode.FOOTER, Opcode.SUMMARY_OFFSET)}
_SUMMARY_FIXED = 512  # statistics, offsets, data end, footer, magic
_SALVAGE_MAX = 1 << 28  # a torn chunk larger than this is not read for its messages


class Corrupt(ValueError):
    """A record whose bytes contradict themselves (a CRC, a length)."""


def _valid(opcode: int) -> bool:
    return opcode in _DATA or opcode >= 0x80  # 0x80 and up: user records, skipped


def records(data, start: int = 0, inner: bool = False) -> tuple[list[tuple[int, int, memoryview]], int]:
    """The complete records of ``data`` from ``start`` as (opcode, offset, body), and where
    they end: at the first record that is incomplete or not a record at all."""
    view, found, pos = memoryview(data), [], start
    while pos + 9 <= len(view):
        opcode, length = _RECORD.unpack_from(view, pos)
        if not (opcode in _CHUNK_INNER if inner else _valid(opcode)) or pos + 9 + length > len(view):
            break
        found.append((opcode, pos, view[pos + 9 : pos + 9 + length]))
        pos += 9 + length
    return found, pos


def _read(record_class, body):
    return record_class.read(ReadDataStream(io.BytesIO(body)))


class McapIndex:
    """What a summary needs, from a file's complete data records in file order (``add``)."""

    def __init__(self) -> None:
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.counts: dict[int, int] = defaultdict(int)  # messages per channel id
        self.message_count = 0
        self.start_time = self.end_time = 0  # log times of the first and last message (0: none)
        self.chunk_indexes: list[ChunkIndex] = []
        self.attachment_indexes: list[AttachmentIndex] = []
        self.metadata_indexes: list[MetadataIndex] = []
        self.metadata: dict[str, dict[str, str]] = {}  # the metadata records by name (the last wins)
        self.end = 0  # the complete data records end here
        self.finished = False  # a data end record was met: what follows is the old summary
        self.summary_bytes = _SUMMARY_FIXED  # about what ``closing`` will write
        self._last: ChunkIndex | None = None  # the chunk the last records belong to
        self._unindexed: dict[int, list[tuple[int, int]]] = {}  # its messages no index record covers yet

    def topics(self) -> dict[str, tuple[str, int]]:
        """topic -> (schema name, messages), for every channel."""
        return {
            ch.topic: (self.schemas[ch.schema_id].name if ch.schema_id in self.schemas else "", self.counts[cid])
            for cid, ch in self.channels.items()
        }

    def feed(self, data, offset: int) -> None:
        """Index what a writer wrote at ``offset``: whole records (or the magic)."""
        if offset == 0 and bytes(data[:8]) == MAGIC:
            self.end = 8
            data, offset = memoryview(data)[8:], 8
        for opcode, pos, body in records(data)[0]:
            if self.finished:
                return
            self.add(opcode, body, offset + pos)

    def add(self, opcode: int, body, offset: int, check_crc: bool = False) -> None:
        """One complete data record, at ``offset`` of the file."""
        if opcode == Opcode.DATA_END:
            self.finished = True
            return
        if opcode == Opcode.MESSAGE_INDEX and self._last is not None:
            channel = _U16.unpack_from(body)[0]
            self._last.message_index_offsets[channel] = offset
            self._last.message_index_length += 9 + len(body)
            self._unindexed.pop(channel, None)
        else:
            self._last, self._unindexed = None, {}
            if opcode == Opcode.CHUNK:
                self._chunk(body, offset, check_crc)
            elif opcode in _CHUNK_INNER:
                self._inner(opcode, body)
            elif opcode == Opcode.METADATA:
                record = _read(Metadata, body)
                self.metadata[record.name] = dict(record.metadata)
                self.metadata_indexes.append(MetadataIndex(offset=offset, length=9 + len(body), name=record.name))
                self.summary_bytes += 40 + len(record.name)
            elif opcode == Opcode.ATTACHMENT:
                a = _read(Attachment, body)
                self.attachment_indexes.append(
                    AttachmentIndex(offset, 9 + len(body), a.log_time, a.create_time, len(a.data), a.name, a.media_type)
                )
                self.summary_bytes += 80 + len(a.name) + len(a.media_type)
        self.end = offset + 9 + len(body)

    def _inner(self, opcode: int, body) -> int | None:
        """A schema, channel or message (in a chunk or not); a message's channel id."""
        if opcode == Opcode.MESSAGE:
            channel, _, log_time = _MESSAGE.unpack_from(body)
            self.counts[channel] += 1
            self.message_count += 1
            self.start_time = log_time if self.message_count == 1 else min(self.start_time, log_time)
            self.end_time = max(self.end_time, log_time)
            return channel
        record = _read(Schema if opcode == Opcode.SCHEMA else Channel, body)
        (self.schemas if opcode == Opcode.SCHEMA else self.channels)[record.id] = record
        self.summary_bytes += 9 + len(body)
        return None

    def _chunk(self, body, offset: int, check_crc: bool) -> None:
        start, end, size, crc, name_len = _CHUNK.unpack_from(body)
        compression = bytes(body[32 : 32 + name_len]).decode()
        data_len = _U64.unpack_from(body, 32 + name_len)[0]
        data = body[40 + name_len : 40 + name_len + data_len]
        if len(data) != data_len:
            raise Corrupt(f"a chunk's records run past its end ({data_len} > {len(data)} bytes)")
        if compression:
            chunk = Chunk(compression, bytes(data), end, start, crc, size)
            data = memoryview(get_chunk_data_stream(chunk)[0].read(size))
        if check_crc and crc and zlib.crc32(data) != crc:
            raise Corrupt("a chunk's CRC does not match its records")
        found, used = records(data, inner=True)
        if used != len(data):
            raise Corrupt("a chunk holds an incomplete record")
        entries: dict[int, list[tuple[int, int]]] = defaultdict(list)
        for opcode, pos, inner in found:
            channel = self._inner(opcode, inner)
            if channel is not None:
                entries[channel].append((_MESSAGE.unpack_from(inner)[2], pos))
        index = ChunkIndex(
            message_start_time=start,
            message_end_time=end,
            chunk_start_offset=offset,
            chunk_length=9 + len(body),
            message_index_offsets={},
            message_index_length=0,
            compression=compression,
            compressed_size=data_len,
            uncompressed_size=size,
        )
        self.chunk_indexes.append(index)
        self._last, self._unindexed = index, dict(entries)
        self.summary_bytes += 80 + len(compression) + 10 * len(entries)


def salvage(body) -> bytes | None:
    """The complete leading messages of a torn (or corrupt) uncompressed chunk, as a chunk
    record of their own; None if it holds none or is compressed."""
    if len(body) < _CHUNK.size + 8:
        return None
    _, _, _, _, name_len = _CHUNK.unpack_from(body)
    if name_len:  # compressed: its records cannot be read without its end
        return None
    found, used = records(memoryview(body)[40:], inner=True)
    times = [_MESSAGE.unpack_from(b)[2] for opcode, _, b in found if opcode == Opcode.MESSAGE]
    if not times:
        return None
    kept = bytes(memoryview(body)[40 : 40 + used])
    builder = RecordBuilder()
    Chunk("", kept, max(times), min(times), zlib.crc32(kept), len(kept)).write(builder)
    return builder.end()


def closing(index: McapIndex, metadata: dict[str, dict[str, str]] | None = None) -> bytes:
    """The records that close a file whose complete data records end at ``index.end``;
    ``metadata`` (name -> strings): metadata records to add after the data (the last word)."""
    builder, start = RecordBuilder(), index.end
    if index._last is not None:  # the last chunk's message indexes were cut: they follow it here
        for channel, entries in index._unindexed.items():
            index._last.message_index_offsets[channel] = start + builder.count
            MessageIndex(channel, entries).write(builder)
        index._last.message_index_length += builder.count
        index._last, index._unindexed = None, {}
    for name, values in (metadata or {}).items():
        offset = builder.count
        Metadata(name=name, metadata=values).write(builder)
        index.metadata[name] = dict(values)
        index.metadata_indexes.append(MetadataIndex(offset=start + offset, length=builder.count - offset, name=name))
    DataEnd(0).write(builder)
    summary_start = start + builder.count
    statistics = Statistics(
        attachment_count=len(index.attachment_indexes),
        channel_count=len(index.channels),
        channel_message_counts=dict(index.counts),
        chunk_count=len(index.chunk_indexes),
        message_count=index.message_count,
        message_end_time=index.end_time,
        message_start_time=index.start_time,
        metadata_count=len(index.metadata_indexes),
        schema_count=len(index.schemas),
    )
    groups = [
        (Opcode.SCHEMA, list(index.schemas.values())),
        (Opcode.CHANNEL, list(index.channels.values())),
        (Opcode.STATISTICS, [statistics]),
        (Opcode.CHUNK_INDEX, index.chunk_indexes),
        (Opcode.ATTACHMENT_INDEX, index.attachment_indexes),
        (Opcode.METADATA_INDEX, index.metadata_indexes),
    ]
    offsets = []
    for opcode, group in groups:
        group_start = builder.count
        for record in group:
            record.write(builder)
        if group:
            offsets.append(SummaryOffset(opcode, start + group_start, builder.count - group_start))
    offsets_start = start + builder.count
    for offset in offsets:
        offset.write(builder)
    data = builder.end()
    summary = data[summary_start - start :]
    crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, offsets_start), zlib.crc32(summary))
    Footer(summary_start=summary_start, summary_offset_start=offsets_start, summary_crc=crc).write(builder)
    return data + builder.end() + MAGIC


class IndexedFile:
    """The MCAP file as the mcap writer sees it (write, tell, flush): each write reaches the
    file whole or raises (OSError), and is indexed once it has."""

    def __init__(self, path: str):
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self.pos = 0
        self.index = McapIndex()

    def write(self, data) -> int:
        _write_all(self.fd, data, self.pos)
        self.index.feed(data, self.pos)
        self.pos += len(data)
        return len(data)

    def tell(self) -> int:
        return self.pos

    def flush(self) -> None:
        pass  # nothing is buffered here

    def close_at(self, end: int, tail: bytes) -> None:
        """Cut what follows ``end`` (a torn record) and write ``tail`` there."""
        os.ftruncate(self.fd, end)
        _write_all(self.fd, tail, end)
        self.close()

    def close(self) -> None:
        if self.fd >= 0:
            fd, self.fd = self.fd, -1
            os.close(fd)


def _write_all(fd: int, data, offset: int) -> None:
    view = memoryview(data).cast("B")
    while view:
        done = os.pwrite(fd, view, offset)
        view, offset = view[done:], offset + done


@dataclass
class Repair:
    """A damaged MCAP file made whole: its first ``keep`` bytes, then ``tail``."""

    path: str
    size: int  # the file's size
    index: McapIndex  # what the whole file holds
    keep: int
    tail: bytes = b""
    torn_at: int | None = None  # where the first incomplete or corrupt record begins
    salvaged: int = 0  # complete messages taken out of that record
    cut: int = 0  # bytes of the file the whole one leaves out
    why: str = ""  # what was wrong at torn_at

    def describe(self, detail: bool = True) -> str:
        """Where the file ends and what was cut, in a sentence's words (``detail``: and why)."""
        if self.torn_at is not None:
            why = f"{self.why}; " if detail else ""
            kept = f"; {self.salvaged} complete messages kept from it" if self.salvaged else ""
            return f"the file ends in a torn record at byte {self.torn_at} ({why}{self.cut} bytes cut{kept})"
        if self.cut:
            return f"its summary was incomplete ({self.cut} bytes after the data cut)"
        return f"it ends after its last complete record (byte {self.keep}), nothing cut"

    def open(self) -> SplicedFile:
        return SplicedFile(self.path, self.keep, self.tail)

    def write_to(self, out: str) -> None:
        """The whole file as a new file ``out`` (synced to disk); on an error none is left."""
        try:
            with open(self.path, "rb") as src, open(out, "xb") as dst:
                left = self.keep
                while left:
                    block = src.read(min(left, 1 << 22))
                    if not block:
                        raise OSError(f"{self.path} shrank while it was copied")
                    dst.write(block)
                    left -= len(block)
                dst.write(self.tail)
                dst.flush()
                os.fsync(dst.fileno())
        except BaseException:
            if os.path.exists(out):
                os.remove(out)
            raise


def examine(path: str, last_word: Callable[[McapIndex], dict[str, dict[str, str]]] | None = None) -> Repair:
    """Read ``path`` record by record up to its first incomplete or corrupt record (or its
    data end) and work out what makes it whole. ConfigError if it is not an MCAP file.
    ``last_word``: the metadata records (``closing``) to end it with, given what it holds."""
    index = McapIndex()
    torn, why, opcode, body = None, "", 0, b""
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if f.read(8) != MAGIC:
            raise ConfigError(f"{path!r} is not an MCAP file (it does not start with the MCAP magic)")
        pos = index.end = 8
        while not index.finished:
            opcode, body = 0, b""
            head = f.read(9)
            if len(head) < 9:
                torn, why = (pos, "its header is cut") if head else (None, "")
                break
            opcode, length = _RECORD.unpack(head)
            if not _valid(opcode) or (pos == 8) != (opcode == Opcode.HEADER):
                torn, why = pos, f"opcode {opcode:#04x} where a record should begin"
                break
            if length > size - pos - 9:  # a torn chunk is read for its complete messages
                torn, why = pos, f"{size - pos - 9} of its {length} bytes written"
                body = f.read(size - pos - 9) if opcode == Opcode.CHUNK and size - pos < _SALVAGE_MAX else b""
                break
            body = f.read(length)
            try:
                index.add(opcode, memoryview(body), pos, check_crc=True)
            except UnsupportedCompressionError as exc:
                raise ConfigError(f"{path!r}: {exc} (install its library to read the file)") from None
            except (Corrupt, McapError, ValueError, struct.error) as exc:
                torn, why = pos, f"corrupt: {exc}"
                break
            pos += 9 + length
    if index.end == 8 and torn == 8:
        raise ConfigError(f"{path!r} holds no complete MCAP record (it ends at byte {size})")
    repair = Repair(path, size, index, keep=index.end, torn_at=torn, why=why)
    rescued = salvage(body) if torn is not None and opcode == Opcode.CHUNK else None
    if rescued is not None:
        before = index.message_count
        index.add(Opcode.CHUNK, memoryview(rescued)[9:], index.end)
        repair.salvaged, repair.tail = index.message_count - before, rescued
    repair.cut = size - repair.keep - len(repair.tail)  # a rescued chunk's header stands for the torn one's
    repair.tail += closing(index, last_word(index) if last_word else None)
    return repair


class SplicedFile:
    """A file's first ``keep`` bytes followed by ``tail``, read-only: a repaired file that
    was never written. (Not an io.RawIOBase: readers wrap those in buffers that close them.)"""

    def __init__(self, path: str, keep: int, tail: bytes) -> None:
        self.keep, self.tail, self._pos = keep, tail, 0
        self._file = open(path, "rb")

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        base = {io.SEEK_SET: 0, io.SEEK_CUR: self._pos, io.SEEK_END: self.keep + len(self.tail)}[whence]
        self._pos = max(0, base + offset)
        return self._pos

    def tell(self) -> int:
        return self._pos

    def read(self, size: int = -1) -> bytes:
        end = self.keep + len(self.tail)
        size = end - self._pos if size < 0 else min(size, end - self._pos)
        if size <= 0:
            return b""
        parts = []
        if self._pos < self.keep:
            self._file.seek(self._pos)
            parts.append(self._file.read(min(size, self.keep - self._pos)))
        start = self._pos + sum(map(len, parts)) - self.keep
        if start >= 0:
            parts.append(self.tail[start : start + size - sum(map(len, parts))])
        data = b"".join(parts)
        self._pos += len(data)
        return data

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> SplicedFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
