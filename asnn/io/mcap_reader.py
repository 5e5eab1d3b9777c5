"""The MCAP container as asnn reads it: records, chunks and the summary, bounded before anything
is allocated (:mod:`asnn.io.rosbag` reads the ROS 2 camera topics out of it).

A bag is read in one of two ways. With a summary whose chunk indexes name each chunk's
channels, only the chunks that hold the wanted topic's messages are read and decompressed
(:func:`bag_records` with a topic); otherwise (a recording that was cut) the file is read through
(:func:`bag_records`). Either way a chunk is read in place, one record at a time: the wanted
topic's messages are copied out, the others only counted, and a record the reader has no use
for (indexes, statistics, attachments, metadata) is skipped unparsed. Bounds: records and
decompressed chunks to :data:`MAX_RECORD_BYTES`, a chunk's records to
:data:`MAX_CHUNK_RECORDS` and to :data:`RECORDS_PER_COMPRESSED_BYTE` per byte of its compressed
data, a message of the wanted topic to :data:`MAX_MESSAGE_BYTES` (a longer one comes as a
:class:`TooLarge`, uncopied), the summary used to :data:`MAX_SUMMARY_BYTES` (read once per file
while small, :func:`bag_summary`).

Record layouts: the MCAP specification, https://mcap.dev/spec.
"""

from __future__ import annotations

import io
import os
import struct
import threading
import zlib
from array import array
from collections.abc import Iterator
from dataclasses import dataclass

from .images import MAX_SIDE

try:
    from mcap.exceptions import McapError
    from mcap.opcode import Opcode
    from mcap.records import Channel, Chunk, Message, Schema
    from mcap.stream_reader import StreamReader
except ImportError as exc:  # the optional extra is missing: say which one, in one line
    raise ImportError("ROS 2 bags (read or written) need the 'ros' extra: pip install 'asnn[ros]'"
                      f" ({exc.name} is missing)") from exc

__all__ = ["MAGIC", "MAX_CHUNK_RECORDS", "MAX_MESSAGE_BYTES", "MAX_RECORD_BYTES",
           "MAX_SUMMARY_BYTES", "READ_ERRORS", "RECORDS_PER_COMPRESSED_BYTE", "TooLarge",
           "bag_records", "bag_summary"]

MAX_RECORD_BYTES = 512 * 2**20  # largest MCAP record or decompressed chunk read
# records read from one chunk (each becomes a Python object in turn): rosbag2's chunks of about
# 1 MB hold a few images, or a few thousand small messages
MAX_CHUNK_RECORDS = 1_000_000
# ... and at most this many per byte of its compressed data, plus a thousand: a record of real
# data does not compress to less than a quarter byte (its times and sequence number alone
# change), where a crafted 3 KB chunk held a million empty messages (seconds a chunk, a pass)
RECORDS_PER_COMPRESSED_BYTE = 4
# largest message of the image topic copied out of a chunk: a MAX_SIDE-square picture of 8 bytes
# a pixel (a 16-bit RGBA png of noise) and room for its header; a larger one is refused before
# it is copied (a 500 MiB "64x64" Image of an 18 KB bag made three 500 MiB copies at once)
MAX_MESSAGE_BYTES = 8 * MAX_SIDE**2 + 2**20
MAX_SUMMARY_BYTES = 64 * 2**20  # largest summary section used (a larger one: read through)
_SUMMARIES_KEPT = 4  # summaries of the latest files kept: a bag is read in three passes
# ... those that hold at most this many bytes, about (a channel or a schema some 1 KB, a chunk
# offset 8 bytes): one of 60,000 channels is some 75 MB, which four files' would hold for the
# life of the process; a long recording's twenty channels in 10,000 chunks, 1.6 MB
_SUMMARY_KEPT_BYTES = 8 * 2**20
_SKIP_BYTES = 2**20  # a record skipped in a read-through is read a piece of this size at a time
_FOOTER_BYTES = 1 + 8 + 20  # the footer record: opcode, length, summary_start, offsets, crc

# --------------------------------------------------------------------------- the file

class _BoundedFile:
    """A binary file whose reads are refused beyond ``limit`` bytes at once: the length fields
    of a corrupt bag cannot make the MCAP reader allocate more than that."""

    def __init__(self, raw, limit: int = MAX_RECORD_BYTES):
        self._raw, self._limit = raw, limit

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        return self._raw.seek(offset, whence)

    def tell(self) -> int:
        return self._raw.tell()

    def read(self, size: int = -1) -> bytes:
        if size is None or size < 0 or size > self._limit:
            raise McapError(f"a record field of {size} bytes, more than the "
                            f"{self._limit} this reader takes")
        return self._raw.read(size)


def _chunk_data(chunk: Chunk) -> bytes:
    """A chunk's records, decompressed: at most its declared ``uncompressed_size`` (at most
    :data:`MAX_RECORD_BYTES`) whatever the compressed frame claims or omits (an lz4 frame
    without a content size inflated 13 MB to 3 GiB), its CRC checked where the writer stored
    one (a chunk overwritten in place may still decompress, and its frames would be read as if
    nothing had happened)."""
    size = chunk.uncompressed_size
    if size > MAX_RECORD_BYTES:
        raise McapError(f"a chunk of {size} bytes uncompressed, more than {MAX_RECORD_BYTES}")
    try:
        if chunk.compression == "zstd":
            import zstandard

            reader = zstandard.ZstdDecompressor().stream_reader(chunk.data)
            data = reader.read(size + 1)
        elif chunk.compression == "lz4":
            import lz4.frame

            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=size + 1)
        elif chunk.compression:
            raise McapError(f"unknown chunk compression {chunk.compression!r}")
        else:
            data = chunk.data
    except McapError:
        raise
    except Exception as exc:  # the decompressors' own error types
        raise McapError(f"a chunk does not decompress ({type(exc).__name__}: "
                        f"{str(exc)[:120]})") from None
    if len(data) != size:
        raise McapError(f"a chunk declared {size} bytes uncompressed decompresses to "
                        f"{'more' if len(data) > size else len(data)}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise McapError("a chunk's data does not match its CRC: the file was damaged")
    return data


_RECORD = struct.Struct("<BQ")  # a record's opcode and length
_MESSAGE = struct.Struct("<HIQQ")  # a message's channel id, sequence, log and publish times
_CHANNEL_MAP_ENTRY = struct.Struct("<HQ")  # a channel id and an offset or a count
# the records a read-through uses; the others (indexes, statistics, attachments, metadata) are
# skipped unparsed: a 64 MiB MessageIndex became 4 million tuples (534 MB, 16 s)
_READ_THROUGH = frozenset({Opcode.HEADER, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE,
                           Opcode.CHUNK, Opcode.DATA_END, Opcode.FOOTER})


@dataclass(frozen=True)
class TooLarge:
    """A message of the topic longer than :data:`MAX_MESSAGE_BYTES`, in place of its Message
    record: its data is not copied."""

    channel_id: int
    size: int


class _Skipped:
    """A record a read-through skips, in place of a parsed one (where a chunk index points)."""


_SKIPPED = _Skipped()


class _Selection:
    """The messages a read makes Message records of: those of ``topic``'s channels, learned
    from the Channel records as they come. A message of another channel is only counted, per
    channel id, in ``counts``: its data is neither copied nor parsed."""

    def __init__(self, topic: str | None = None, counts: dict[int, int] | None = None):
        self.topic = topic
        self.counts = counts if counts is not None else {}
        self.ids: set[int] = set()

    def channel(self, channel: Channel) -> Channel:
        if channel.topic == self.topic:
            self.ids.add(channel.id)
        else:  # an id declared again for another topic
            self.ids.discard(channel.id)
        return channel

    def take(self, channel_id: int) -> bool:
        """Whether a message of ``channel_id`` is the topic's (one that is not is counted)."""
        if channel_id in self.ids:
            return True
        self.counts[channel_id] = self.counts.get(channel_id, 0) + 1
        return False


def _string(record: memoryview, at: int) -> tuple[str, int]:
    """The length-prefixed UTF-8 string of a record at ``at``, and the offset after it."""
    (size,) = struct.unpack_from("<I", record, at)
    at += 4
    if size > len(record) - at:
        raise McapError(f"a string of {size} bytes runs past the end of its record")
    return str(record[at:at + size], "utf-8"), at + size


def _schema(record: memoryview) -> Schema:
    """A Schema record's id, name and encoding; its text is not kept (a message is decoded by its
    type's own definition)."""
    (schema_id,) = struct.unpack_from("<H", record)
    name, at = _string(record, 2)
    encoding, _ = _string(record, at)
    return Schema(id=schema_id, name=name, encoding=encoding, data=b"")


def _channel(record: memoryview) -> Channel:
    """A Channel record without its metadata (not used; a map of millions of tiny pairs would be
    as many objects)."""
    channel_id, schema_id = struct.unpack_from("<HH", record)
    topic, at = _string(record, 4)
    encoding, _ = _string(record, at)
    return Channel(id=channel_id, schema_id=schema_id, topic=topic, message_encoding=encoding,
                   metadata={})


def _channel_map(record: memoryview, at: int) -> Iterator[tuple[int, int]]:
    """The (channel id, value) pairs of a record's ``Map<uint16, uint64>`` at ``at``."""
    (size,) = struct.unpack_from("<I", record, at)
    if size > len(record) - at - 4 or size % _CHANNEL_MAP_ENTRY.size:
        raise McapError(f"a map of {size} bytes does not fit its record")
    return _CHANNEL_MAP_ENTRY.iter_unpack(record[at + 4:at + 4 + size])


def _message(head: tuple, data) -> Message | TooLarge:
    """The Message record of the topic whose header fields are ``head``, its data (a buffer)
    copied; a TooLarge one past :data:`MAX_MESSAGE_BYTES`."""
    channel_id, sequence, log_time, publish_time = head
    if len(data) > MAX_MESSAGE_BYTES:
        return TooLarge(channel_id, len(data))
    return Message(channel_id=channel_id, sequence=sequence, log_time=log_time,
                   publish_time=publish_time, data=bytes(data))


def _chunk_record_limit(chunk: Chunk) -> int:
    """The most records read from a chunk: :data:`MAX_CHUNK_RECORDS`, and
    :data:`RECORDS_PER_COMPRESSED_BYTE` per byte of its compressed data (plus a thousand)."""
    if not chunk.compression:
        return MAX_CHUNK_RECORDS
    return min(MAX_CHUNK_RECORDS, RECORDS_PER_COMPRESSED_BYTE * len(chunk.data) + 1000)


def _chunk_records(chunk: Chunk, selection: _Selection) -> Iterator:
    """The Schema and Channel records of a chunk and the Message records of ``selection``'s
    topic, one at a time: a 52 KB bag whose chunk held 12 million tiny records made as many
    objects at once (5 GB) where the mcap library breaks a chunk up into a list. The other
    messages are counted, never copied (the chunk is read in place); one of the topic longer
    than :data:`MAX_MESSAGE_BYTES` comes as a :class:`TooLarge`. At most
    :func:`_chunk_record_limit` records, and a record of opcode 0 (reserved: zeros where
    records should be) ends it."""
    data = _chunk_data(chunk)
    view, end, at = memoryview(data), len(data), 0
    most = _chunk_record_limit(chunk)
    for _ in range(most):
        if at >= end:
            return
        if end - at < _RECORD.size:
            raise McapError("a chunk ends within a record's header")
        opcode, length = _RECORD.unpack_from(view, at)
        at += _RECORD.size
        if opcode == 0:
            raise McapError("a chunk holds a record of opcode 0 (zeros where records should "
                            "be: the file was damaged)")
        if length > end - at:
            raise McapError(f"a chunk's record of {length} bytes runs past its end")
        record, at = view[at:at + length], at + length
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE.size:
                raise McapError(f"a chunk's message record of {length} bytes is shorter than "
                                "a message's header")
            head = _MESSAGE.unpack_from(record)
            if selection.take(head[0]):
                yield _message(head, record[_MESSAGE.size:])
        elif opcode == Opcode.CHANNEL:
            yield selection.channel(_channel(record))
        elif opcode == Opcode.SCHEMA:
            yield _schema(record)
    if at < end:
        raise McapError(f"a chunk of more than {most} records"
                        + (f" in {len(chunk.data)} bytes compressed (records of real data take "
                           f"more than 1/{RECORDS_PER_COMPRESSED_BYTE} byte each)"
                           if most < MAX_CHUNK_RECORDS else ""))


class _StreamReader(StreamReader):
    """The mcap library's reader, refusing a record of opcode 0 (reserved) at once (a file of
    zeros reads as 9-byte records of it, which the library skips one by one: an 8 GiB sparse
    file took about an hour), and parsing only what a read-through uses, as
    :func:`_chunk_records` does: Schema and Channel records without their text and metadata,
    the Message records of ``selection``'s topic (the others counted and skipped), chunks; the
    other records are skipped unparsed (:data:`_SKIPPED`)."""

    def __init__(self, stream, selection: _Selection | None = None, **kwargs):
        super().__init__(stream, **kwargs)
        self._selection = selection if selection is not None else _Selection()

    def _read_record(self, opcode: int, length: int):
        if opcode == 0:
            raise McapError("a record of opcode 0 (zeros where records should be: the file "
                            "was damaged)")
        if opcode not in _READ_THROUGH:
            self._skip(length)
            return _SKIPPED
        if opcode == Opcode.SCHEMA:
            return _schema(memoryview(self._stream.read(length)))
        if opcode == Opcode.CHANNEL:
            return self._selection.channel(_channel(memoryview(self._stream.read(length))))
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE.size:
                raise McapError(f"a message record of {length} bytes is shorter than a "
                                "message's header")
            head = _MESSAGE.unpack(self._stream.read(_MESSAGE.size))
            size = length - _MESSAGE.size
            if not self._selection.take(head[0]):
                self._skip(size)
                return _SKIPPED
            if size > MAX_MESSAGE_BYTES:
                self._skip(size)
                return TooLarge(head[0], size)
            return _message(head, self._stream.read(size))
        return super()._read_record(opcode, length)

    def _skip(self, size: int) -> None:
        """Read past ``size`` bytes, a piece at a time (a file cut short ends it)."""
        while size > 0:
            size -= len(self._stream.read(min(size, _SKIP_BYTES)))


def bag_records(fh, topic: str | None = None, counts: dict[int, int] | None = None) -> Iterator:
    """Schema and Channel records of an MCAP file in file order, with the Message records of
    ``topic``'s channels (bounded).

    The messages of other channels are counted per channel id in ``counts`` (when given),
    without a copy of their data; a message of the topic longer than :data:`MAX_MESSAGE_BYTES`
    comes as a :class:`TooLarge`, not copied either. With ``topic``, a bag whose summary
    indexes its chunks has only the chunks that hold ``topic``'s messages read and decompressed
    (a camera's images beside lidar scans are a small part of a bag). Otherwise, and for a bag
    without a chunk index (a recording that was cut), the file is read through.
    """
    selection = _Selection(topic, counts)
    chunks = _topic_chunks(fh, topic) if topic is not None else None
    if chunks is None:
        fh.seek(0)
        reader = _StreamReader(_BoundedFile(fh), selection, emit_chunks=True,
                               record_size_limit=MAX_RECORD_BYTES)
        for record in reader.records:
            if isinstance(record, Chunk):
                yield from _chunk_records(record, selection)
            elif isinstance(record, (Schema, Channel, Message, TooLarge)):
                yield record
        return
    summary, offsets = chunks
    yield from summary.schemas.values()
    for channel in summary.channels.values():
        yield selection.channel(channel)
    for offset in offsets:
        fh.seek(offset)
        reader = _StreamReader(_BoundedFile(fh), selection, skip_magic=True, emit_chunks=True,
                               record_size_limit=MAX_RECORD_BYTES)
        record = next(iter(reader.records), None)
        if not isinstance(record, Chunk):
            raise McapError(f"the chunk index points at offset {offset}, where no chunk is")
        yield from _chunk_records(record, selection)


@dataclass
class _Summary:
    """What the reader uses of a bag's summary section.

    Attributes
    ----------
    schemas, channels : dict
        By id, as :func:`_schema` and :func:`_channel` read them.
    counts : dict or None
        Messages per channel id (the statistics; None without them, empty when they give no
        counts).
    chunks : dict
        Channel id to the start offsets of the chunks its messages are in: the chunk indexes
        alone would be some 800 bytes of objects each (a 60 MB summary of 723k of them: 605 MB).
    chunk_count : int
        Chunk indexes read.
    indexed : bool
        Whether every chunk index says which channels its chunk holds.
    """

    schemas: dict[int, Schema]
    channels: dict[int, Channel]
    counts: dict[int, int] | None
    chunks: dict[int, array]
    chunk_count: int = 0
    indexed: bool = True

    def weight(self) -> int:
        """About the bytes it holds: what keeping it costs."""
        return (1024 * (len(self.schemas) + len(self.channels))
                + 8 * sum(len(offsets) for offsets in self.chunks.values()))


_summaries: dict[tuple, _Summary | None] = {}
_summaries_lock = threading.Lock()


def bag_summary(fh) -> _Summary | None:
    """The bag's summary section, or None when it has none, it does not parse, or it is larger
    than :data:`MAX_SUMMARY_BYTES`. Read once for the latest :data:`_SUMMARIES_KEPT` files
    (known by their identity, size, time of change and footer) whose summary holds at most
    about :data:`_SUMMARY_KEPT_BYTES`: a bag is read in three passes (its topics, the first
    frames, the frames), a camera's replay in one a loop."""
    try:
        info = os.fstat(fh.fileno())
        end = fh.seek(0, io.SEEK_END)
        fh.seek(max(0, end - len(MAGIC) - _FOOTER_BYTES))
        key = (info.st_dev, info.st_ino, end, info.st_mtime_ns, info.st_ctime_ns,
               fh.read(_FOOTER_BYTES + len(MAGIC)), MAX_SUMMARY_BYTES)
    except (AttributeError, OSError, ValueError):  # not a file of its own
        return _read_summary(fh)
    with _summaries_lock:
        if key in _summaries:
            return _summaries[key]
    summary = _read_summary(fh)
    if summary is not None and summary.weight() > _SUMMARY_KEPT_BYTES:
        return summary  # read again on each pass rather than kept
    with _summaries_lock:
        while len(_summaries) >= _SUMMARIES_KEPT:
            _summaries.pop(next(iter(_summaries)))
        _summaries[key] = summary
    return summary


def _read_summary(fh) -> _Summary | None:
    """:func:`bag_summary`, read: the section is read whole (at most :data:`MAX_SUMMARY_BYTES`) and
    its records one at a time, the chunk indexes kept as offsets per channel."""
    try:
        end = fh.seek(0, io.SEEK_END)
        if end < len(MAGIC) * 2 + _FOOTER_BYTES:
            return None
        fh.seek(0)
        if fh.read(len(MAGIC)) != MAGIC:
            return None
        fh.seek(end - len(MAGIC) - _FOOTER_BYTES)
        footer = fh.read(_FOOTER_BYTES + len(MAGIC))
        if footer[0] != Opcode.FOOTER or footer[_FOOTER_BYTES:] != MAGIC:
            return None
        (start,) = struct.unpack_from("<Q", footer, 9)  # the footer's summary_start
        if start == 0 or not 0 < end - start <= MAX_SUMMARY_BYTES:
            return None
        fh.seek(start)
        return _parse_summary(memoryview(fh.read(end - start - len(MAGIC))))
    except Exception:  # no footer or summary (a recording that was cut)
        return None


def _parse_summary(section: memoryview) -> _Summary:
    """A summary section's records, up to the footer (McapError where one runs past it)."""
    summary = _Summary(schemas={}, channels={}, counts=None, chunks={})
    at = 0
    while True:
        opcode, length = _RECORD.unpack_from(section, at)
        at += _RECORD.size
        if length > len(section) - at:
            raise McapError(f"a summary record of {length} bytes runs past the summary's end")
        record, at = section[at:at + length], at + length
        if opcode == Opcode.FOOTER:
            if any(c.schema_id and c.schema_id not in summary.schemas
                   for c in summary.channels.values()):
                # a valid MCAP that does not repeat its schemas here (a writer's
                # repeat_schemas=False): the channels' types are in the data section only,
                # so the file is read through as one without channels in its summary is
                summary.channels = {}
            return summary
        if opcode == Opcode.SCHEMA:
            schema = _schema(record)
            summary.schemas[schema.id] = schema
        elif opcode == Opcode.CHANNEL:
            channel = _channel(record)
            summary.channels[channel.id] = channel
        elif opcode == Opcode.STATISTICS:  # the message counts follow 42 bytes of totals
            summary.counts = dict(_channel_map(record, 42))
        elif opcode == Opcode.CHUNK_INDEX:  # the chunk's start follows its message times
            (offset,) = struct.unpack_from("<Q", record, 16)
            ids = {channel_id for channel_id, _ in _channel_map(record, 32)}
            summary.chunk_count += 1
            summary.indexed = summary.indexed and bool(ids)
            for channel_id in ids:
                summary.chunks.setdefault(channel_id, array("Q")).append(offset)


def _topic_chunks(fh, topic: str) -> tuple | None:
    """The bag's summary and the start offsets, in file order, of the chunks holding
    ``topic``'s messages; None when the summary does not say (no summary, no chunk index, a
    chunk index without message indexes). An offset indexed twice is read once."""
    summary = bag_summary(fh)
    if summary is None or not summary.chunk_count or not summary.indexed:
        return None
    ids = {c.id for c in summary.channels.values() if c.topic == topic}
    if not ids:
        return None
    return summary, sorted({offset for i in ids for offset in summary.chunks.get(i, ())})


# reading errors a corrupt or truncated file raises from the MCAP library and the decompressors
READ_ERRORS = (McapError, OSError, ValueError, struct.error, KeyError, EOFError, RuntimeError,
            MemoryError, OverflowError)
MAGIC = b"\x89MCAP0\r\n"


