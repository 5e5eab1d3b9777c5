"""ROS 2 bags in MCAP (rosbag2's default storage): camera topics in, frames out.

Reads ``sensor_msgs/msg/Image`` and ``sensor_msgs/msg/CompressedImage`` topics with the MCAP
project's reader (``mcap``) and its ROS 2 decoder (``mcap-ros2-support``), the optional ``ros``
extra, and Foxglove's ``foxglove.RawImage`` and ``foxglove.CompressedImage`` in protobuf (what
Foxglove's recorders and ``asnn detect --mcap`` write; :mod:`asnn.io.foxglove_images`).
Everything read from a bag is bounded before it is allocated: the container's records, chunks
and summary as :mod:`asnn.io.mcap_reader` reads them (the image topic's messages to
:data:`~asnn.io.mcap_reader.MAX_MESSAGE_BYTES`, the others never copied), pictures to
:data:`asnn.io.images.MAX_SIDE` per side with their pixel count checked against the data they
come with (a compressed picture's header must describe a whole image its data can hold,
:func:`asnn.io.images.check_encoded`).

A frame's time is its ``header.stamp`` relative to the first frame's (the recorder's log time
when the first stamp is zero: drivers that leave it unset). A stamp before the latest one taken
is refused (``stamp-backwards``), unless :data:`CLOCK_RESET_FRAMES` of them in a row advance among
themselves: a camera's clock reset, on which the times are re-based (``clock-reset``,
:meth:`BagClip.frames`). A stamp left unset among header stamps takes its log time where that can
stand for one, else the latest frame's time, which is reported (``stamp-unset``).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..params import MAX_FRAME_GAP_S
from .files import seekable_target
from .foxglove_images import (FOXGLOVE_COMPRESSED_IMAGE, FOXGLOVE_IMAGE_SCHEMAS,
                              FOXGLOVE_RAW_IMAGE, decode_compressed_image, decode_raw_image)
from .images import MAX_SIDE, ImageError, decode_encoded, to_uint8
from .mcap_reader import (MAGIC, MAX_MESSAGE_BYTES, READ_ERRORS, TooLarge, bag_records,
                          bag_summary)
from .sources import CLOCK_RESET, CLOCK_RESET_FRAMES, STAMP_UNSET, SourceError

try:
    import yaml
    from mcap.records import Channel, Message, Schema
    from mcap_ros2.decoder import DecoderFactory
    from mcap_ros2.writer import Writer as Ros2Writer
except ImportError as exc:  # the optional extra is missing: say which one, in one line
    raise ImportError("ROS 2 bags (read or written) need the 'ros' extra: pip install 'asnn[ros]'"
                      f" ({exc.name} is missing)") from exc

__all__ = ["BagClip", "CLOCK_RESET_FRAMES", "COMPRESSED_IMAGE", "IMAGE", "IMAGE_SCHEMAS",
           "RAW_ENCODINGS", "TopicInfo", "bag_files", "bag_topics",
           "choose_topic", "compressed_image_message", "image_from_compressed", "image_from_raw",
           "open_bag", "raw_image_message", "register_image_type", "ros_name_token", "ros_time_ns",
           "ros_topic", "write_bag", "IMAGE_MSGDEF", "COMPRESSED_IMAGE_MSGDEF"]

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
IMAGE_SCHEMAS = (IMAGE, COMPRESSED_IMAGE, *FOXGLOVE_IMAGE_SCHEMAS)
RAW_SCHEMAS = (IMAGE, FOXGLOVE_RAW_IMAGE)  # the others are compressed: jpeg or png
FPS_PROBE = 30                  # frames whose stamps estimate a bag's nominal frame rate

# The message definitions rosbag2 embeds as schemas (ros2msg: the type, then its dependencies).
_HEADER_MSGDEF = """
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec"""
IMAGE_MSGDEF = """std_msgs/Header header
uint32 height
uint32 width
string encoding
uint8 is_bigendian
uint32 step
uint8[] data""" + _HEADER_MSGDEF
COMPRESSED_IMAGE_MSGDEF = """std_msgs/Header header
string format
uint8[] data""" + _HEADER_MSGDEF

# sensor_msgs/image_encodings: bytes per pixel and the conversion to gray or BGR uint8
_BAYER = {"bayer_rggb8": cv2.COLOR_BayerBG2BGR, "bayer_bggr8": cv2.COLOR_BayerRG2BGR,
          "bayer_gbrg8": cv2.COLOR_BayerGR2BGR, "bayer_grbg8": cv2.COLOR_BayerGB2BGR}
RAW_ENCODINGS: dict[str, int] = {
    "mono8": 1, "8UC1": 1, "mono16": 2, "16UC1": 2, "bgr8": 3, "8UC3": 3, "rgb8": 3,
    "bgra8": 4, "8UC4": 4, "rgba8": 4, "yuv422": 2, "uyvy": 2, "yuv422_yuy2": 2, "yuyv": 2,
    **dict.fromkeys(_BAYER, 1)}


# Foxglove's images, decoded by their published field numbers (protobuf, no schema text read)
_FOXGLOVE_DECODERS = {FOXGLOVE_COMPRESSED_IMAGE: decode_compressed_image,
                      FOXGLOVE_RAW_IMAGE: decode_raw_image}


@dataclass(frozen=True)
class TopicInfo:
    """A topic of a bag: its name, message type, and message count (None when the bag has no
    summary that says)."""

    name: str
    schema: str
    count: int | None

    @property
    def is_image(self) -> bool:
        return self.schema in IMAGE_SCHEMAS


# --------------------------------------------------------------------------- pictures

def image_from_raw(width: int, height: int, encoding: str, is_bigendian: int, step: int,
                   data: bytes) -> np.ndarray:
    """The pixels of a ``sensor_msgs/msg/Image`` as gray (H, W) or BGR (H, W, 3) uint8.

    Parameters
    ----------
    width, height : int
        Sides, 1..``MAX_SIDE``.
    encoding : str
        One of :data:`RAW_ENCODINGS` (mono8, mono16, rgb8, bgr8, rgba8, bgra8, their
        ``8UC*``/``16UC1`` names, the 8-bit Bayer patterns, and yuv422 as UYVY or YUY2).
    is_bigendian : int
        Byte order of 16-bit pixels.
    step : int
        Bytes per row, at least ``width`` times the bytes per pixel (rows may be padded).
    data : bytes
        ``step * height`` bytes (the last row's padding may be missing).

    Returns
    -------
    ndarray
        A new array: gray for mono encodings (16-bit ones by their high byte), BGR otherwise.

    Raises
    ------
    ImageError
        ``unknown-encoding``, ``bad-size`` (sides, or a step shorter than a row) or
        ``bad-pixels`` (data of another length than the sides and step say), all checked
        before anything is allocated.
    """
    bpp = RAW_ENCODINGS.get(encoding)
    if bpp is None:
        raise ImageError("unknown-encoding", f"image encoding {_shown(encoding)!r} is not one of "
                         f"{', '.join(RAW_ENCODINGS)}")
    if not (1 <= width <= MAX_SIDE and 1 <= height <= MAX_SIDE):
        raise ImageError("bad-size", f"image of {width}x{height}; sides must be 1..{MAX_SIDE}")
    row = width * bpp
    if step < row:
        raise ImageError("bad-size", f"step {step} is shorter than a row of {width} {encoding} "
                         f"pixels ({row} bytes)")
    least, most = step * (height - 1) + row, step * height
    if not least <= len(data) <= most:
        raise ImageError("bad-pixels", f"{width}x{height} {encoding} with step {step} needs "
                         f"{most} bytes, got {len(data)}")
    if bpp == 2 and encoding in ("mono16", "16UC1"):
        pixels = np.ndarray((height, width), dtype=">u2" if is_bigendian else "<u2",
                            buffer=data, strides=(step, 2))
        return to_uint8(pixels.astype(np.uint16))
    rows = np.ndarray((height, row), dtype=np.uint8, buffer=data, strides=(step, 1))
    if bpp == 1 and encoding in _BAYER:
        return cv2.cvtColor(np.ascontiguousarray(rows), _BAYER[encoding])
    if bpp == 1:
        return rows.copy()
    contiguous = np.ascontiguousarray(rows)  # a copy only where the rows were padded
    pixels = contiguous.reshape(height, width, bpp)
    if encoding in ("yuv422", "uyvy", "yuv422_yuy2", "yuyv"):
        if width % 2:
            raise ImageError("bad-size", f"{encoding} needs an even width, got {width}")
        code = cv2.COLOR_YUV2BGR_UYVY if encoding in ("yuv422", "uyvy") else cv2.COLOR_YUV2BGR_YUY2
        return cv2.cvtColor(pixels, code)
    if encoding == "rgb8":
        return cv2.cvtColor(pixels, cv2.COLOR_RGB2BGR)
    if encoding == "rgba8":
        return cv2.cvtColor(pixels, cv2.COLOR_RGBA2BGR)
    if bpp == 4:
        return cv2.cvtColor(pixels, cv2.COLOR_BGRA2BGR)
    # bgr8, 8UC3: unpadded rows are still the message's (read-only) bytes
    return pixels if contiguous is not rows else pixels.copy()


def image_from_compressed(format: str, data: bytes) -> np.ndarray:
    """The pixels of a ``sensor_msgs/msg/CompressedImage`` (jpeg or png, as image_transport
    names them: ``jpeg``, ``png``, ``rgb8; jpeg compressed bgr8``...) as gray or BGR uint8.

    Raises
    ------
    ImageError
        ``unknown-encoding`` for other formats (``compressedDepth`` included: a depth map is not
        a camera picture), ``bad-image`` or ``bad-size`` as in
        :func:`asnn.io.images.decode_encoded`.
    """
    name = format.lower()
    if "compresseddepth" in name:
        kind = None
    elif "jpeg" in name or "jpg" in name:
        kind = "jpeg"
    elif "png" in name:
        kind = "png"
    else:
        kind = None
    if kind is None:
        raise ImageError("unknown-encoding", f"compressed image format {_shown(format)!r}; "
                         "jpeg and png are read")
    return to_uint8(decode_encoded(data, kind, max_depth=16))

def _corrupt(path: Path, exc: BaseException, where: str) -> SourceError:
    detail = str(exc).strip() or type(exc).__name__
    return SourceError(f"{path}: truncated or corrupt bag {where} ({detail[:160]}); "
                       "`mcap recover` can repair a bag whose recording was cut", "corrupt-bag")


def bag_topics(path: str | Path) -> dict[str, TopicInfo]:
    """The topics of a bag, from its summary, or by reading it through when it has none
    (a recording that was cut). A cut bag lists the topics before the cut.

    Raises
    ------
    SourceError
        If the file is missing or not an MCAP file.
    """
    path = Path(path)
    if not path.is_file():
        if path.exists():  # a pipe, a device: an MCAP file is read where its summary is
            raise SourceError(f"{path}: not a regular file", "not-a-bag")
        raise SourceError(f"{path}: no such file", "missing")
    with open(path, "rb") as raw:
        if raw.read(len(MAGIC)) != MAGIC:
            raise SourceError(f"{path}: not an MCAP file", "not-a-bag")
        summary = bag_summary(raw)  # None for a recording that was cut: read it through below
        if summary is not None and summary.channels:
            return _by_topic(TopicInfo(c.topic, _schema_name(summary.schemas.get(c.schema_id)),
                                       # an empty map: the statistic is not available
                                       summary.counts.get(c.id, 0) if summary.counts else None)
                             for c in sorted(summary.channels.values(), key=lambda c: c.id))
        raw.seek(0)
        schemas: dict[int, str] = {}
        channels: dict[int, Channel] = {}
        counts: dict[int, int] = {}  # the messages, counted without being copied
        damaged = False
        try:
            for record in bag_records(raw, counts=counts):
                if isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    channels[record.id] = record
        except READ_ERRORS as exc:
            if not channels:
                raise _corrupt(path, exc, "before any topic") from None
            damaged = True
        # a topic without a message before the damage is not known to hold none: reading it
        # names the damage (a "holds no message" error would hide it)
        return _by_topic(TopicInfo(c.topic, schemas.get(c.schema_id, ""),
                                   counts.get(c.id, None if damaged else 0))
                         for c in channels.values())


def _by_topic(channels: Iterable[TopicInfo]) -> dict[str, TopicInfo]:
    """Channels (or the topics of a split bag's parts), in the order they were declared, as
    topics: a topic recorded on several channels (recordings merged, a publisher that advertised
    again, a bag split in parts) has the type of its first that names one (a later channel of
    another type is refused when it is read) and their counts summed (None where one does not
    say)."""
    topics: dict[str, TopicInfo] = {}
    for info in channels:
        seen = topics.get(info.name)
        if seen is not None:
            count = None if seen.count is None or info.count is None else seen.count + info.count
            # the type of the first channel that holds a message, where the counts say so
            # (a channel declared first and never used decides nothing)
            schema = (info.schema if seen.count == 0 and info.count and info.schema
                      else seen.schema or info.schema)
            info = TopicInfo(info.name, schema, count)
        topics[info.name] = info
    return topics


def _merged_topics(parts: Sequence[Path]) -> dict[str, TopicInfo]:
    """The topics of a bag's parts together (:func:`_by_topic`)."""
    return _by_topic(info for part in parts for info in bag_topics(part).values())


def _schema_name(schema: Schema | None) -> str:
    return schema.name if schema is not None else ""


def _shown(text: str, most: int = 80) -> str:
    """A name or label read from a bag, for an error line: its first ``most`` characters and how
    long it was (a probe's 20 MB encoding string made a 20 MB "one-line" error)."""
    text = str(text)
    return text if len(text) <= most else f"{text[:most]}... ({len(text)} characters)"


def _names(topics: dict[str, TopicInfo], most: int = 20) -> str:
    """The first ``most`` topic names in order, for an error line."""
    names = sorted(topics)
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(_shown(n) for n in names[:most]) + more


def _topic_list(topics: dict[str, TopicInfo], most: int = 20) -> str:
    """The first ``most`` topics with their types, for a one-line error."""
    names = [f"{_shown(t.name)} ({_shown(t.schema) or 'no schema'})"
             for t in list(topics.values())[:most]]
    more = f" and {len(topics) - most} more" if len(topics) > most else ""
    return (", ".join(names) or "none") + more


def choose_topic(path: Path, topics: dict[str, TopicInfo], topic: str | None) -> TopicInfo:
    """The image topic to read: ``topic``, or the bag's only image topic.

    Raises
    ------
    SourceError
        For a topic the bag does not have, that is not an image topic or holds no message,
        and, without ``topic``, for a bag with no image topic or several (the error lists them).
    """
    images = {name: t for name, t in topics.items() if t.is_image}
    if topic is None:
        if not images:
            raise SourceError(f"{path}: no image topic ({' or '.join(IMAGE_SCHEMAS)}); "
                              f"topics: {_topic_list(topics)}", "no-topic")
        if len(images) > 1:
            raise SourceError(f"{path}: several image topics, choose one with --topic (or "
                              f"FILE.mcap#TOPIC): {_names(images)}", "several-topics")
        topic = next(iter(images))
    info = topics.get(topic)
    if info is None:
        raise SourceError(f"{path}: no topic {_shown(topic)!r}; image topics: "
                          f"{_names(images) or 'none'}", "no-topic")
    if not info.is_image:
        raise SourceError(f"{path}: topic {_shown(topic)} is "
                          f"{_shown(info.schema) or 'schemaless'}, not "
                          f"{' or '.join(IMAGE_SCHEMAS)}", "no-topic")
    if info.count == 0:
        raise SourceError(f"{path}: topic {_shown(topic)} holds no message", "empty-topic")
    return info


class BagClip:
    """The frames of one image topic of a bag, read lazily in file order.

    Attributes
    ----------
    path : Path
        The bag file, or the directory of a bag split into several files.
    parts : list of Path
        The bag's files, read one after the other.
    topic : str
    schema : str
        One of :data:`IMAGE_SCHEMAS`: ``sensor_msgs/msg/Image``,
        ``sensor_msgs/msg/CompressedImage``, ``foxglove.RawImage`` or
        ``foxglove.CompressedImage``.
    frame_count : int
        Messages on the topic, from the bag's summaries (0 when they have none).
    start_ns : int
        Time of the first frame, nanoseconds since the epoch.
    clock : {'header', 'log'}
        Where frame times come from: ``header.stamp`` (a frame whose stamp is zero: its log
        time), or the recorder's log time when the first frame's stamp is zero.
    fps : float
        Nominal frame rate: the median rate of the first frames (20 when there is one).
    width, height : int
        Size of the first frame.
    frame_id : str
        ``header.frame_id`` of the first frame (its first 256 characters).
    """

    def __init__(self, path: str | Path, topic: str | None = None, *,
                 parts: Sequence[str | Path] | None = None):
        self.path = Path(path)
        self.parts = [Path(p) for p in parts] if parts else [self.path]
        # a split bag's topics are those of all its parts: a camera that started late has its
        # frames in a later part only
        info = choose_topic(self.path, _merged_topics(self.parts), topic)
        self.topic, self.schema = info.name, info.schema
        self._topic = _shown(self.topic)  # in error lines
        self.frame_count = info.count or 0
        self.clock = "header"
        self.start_ns = 0
        first, stamps, errors = None, [], []
        # a cut within the first frames is reported when they are read, not here
        probe = self._messages(lambda reason, message: errors.append(SourceError(message, reason)))
        for index, item in enumerate(probe):
            if index == 0:
                message, log_time, number = item
                if _stamp_ns(message) == 0:
                    self.clock = "log"
                first = self._decode(message, number)
                # the results' frame of reference; a name, not a payload (at most 256 characters)
                self.frame_id = str(getattr(message.header, "frame_id", ""))[:256]
            stamps.append(self._time_ns(*item[:2]))
            if len(stamps) >= FPS_PROBE:
                break
        probe.close()
        if first is None:
            raise errors[0] if errors else SourceError(
                f"{self.path}: topic {self._topic} holds no message", "empty-topic")
        self.height, self.width = first.shape[:2]
        self.start_ns = stamps[0]
        stamps = np.asarray(stamps, dtype=np.int64)
        if self.clock == "log":  # a recorder's log times of frames that arrived swapped: the
            stamps = np.sort(stamps)  # spacing whatever the order (header stamps: a clock
            # that steps back a little would interleave with itself, sorted)
        steps = np.diff(stamps)
        steps = steps[steps > 0]
        self.fps = float(1e9 / np.median(steps)) if steps.size else 20.0

    def _time_ns(self, message, log_time: int) -> int:
        if self.clock == "header":
            stamp = _stamp_ns(message)
            if stamp:  # one left unset (zero) partway through: its log time, not 1970
                return stamp
        return int(log_time)

    def _messages(self, on_error: Callable[[str, str], None] | None) -> Iterator:
        """(decoded message, log time) of the topic, part after part; a corrupt message or a
        cut is reported to ``on_error`` (the iteration ends at a cut) or raised when there is
        none."""
        index = 0
        for part in self.parts:
            index, cut = yield from self._part_messages(part, index, on_error)
            if cut:  # the parts after it are not read
                return

    def _part_messages(self, path: Path, index: int,
                       on_error: Callable[[str, str], None] | None) -> Iterator:
        """:meth:`_messages` of one file, whose first message is the topic's ``index``-th;
        returns the index after its last message and whether it ended in a cut."""
        decoders = DecoderFactory()
        channels: dict[int, tuple[Schema | None, Callable | None]] = {}
        schemas: dict[int, Schema] = {}
        with open(path, "rb") as fh:
            records = bag_records(fh, self.topic)
            while True:
                try:
                    record = next(records)
                except StopIteration:
                    return index, False
                except READ_ERRORS as exc:
                    error = _corrupt(path, exc, f"after {index} messages of {self._topic}")
                    if on_error is None:
                        raise error from None
                    on_error(error.reason, str(error))
                    return index, True
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel) and record.topic == self.topic:
                    try:
                        channels[record.id] = self._decoder(decoders, record, schemas)
                    except SourceError as error:
                        # said at its first message: a channel declared and never used (a
                        # recorder's idle subscription of another type) stops nothing
                        channels[record.id] = error
                elif isinstance(record, Message) and isinstance(
                        channels.get(record.channel_id), SourceError):
                    if on_error is None:
                        raise channels[record.channel_id]
                    error = channels[record.channel_id]
                    on_error(error.reason, str(error))
                    return index, True
                elif isinstance(record, TooLarge) and record.channel_id in channels:
                    error = SourceError(f"{path}: {self._topic} message {index} is "
                                        f"{record.size} bytes, more than the "
                                        f"{MAX_MESSAGE_BYTES} of the largest picture read "
                                        f"({MAX_SIDE}x{MAX_SIDE})", "bad-message")
                    if on_error is None:
                        raise error
                    on_error(error.reason, str(error))
                    index += 1
                elif isinstance(record, Message) and record.channel_id in channels:
                    decode = channels[record.channel_id]
                    try:
                        message = decode(record.data)
                        _stamp_ns(message)  # a message without a header is not an image
                    except Exception as exc:  # bytes that are no Image of the type's definition
                        error = SourceError(f"{path}: {self._topic} message {index} does "
                                            f"not decode ({type(exc).__name__}: "
                                            f"{str(exc)[:120]})", "bad-message")
                        if on_error is None:
                            raise error from None
                        on_error(error.reason, str(error))
                    else:
                        yield message, record.log_time, index
                    index += 1

    def _decoder(self, decoders: DecoderFactory, channel: Channel,
                 schemas: dict[int, Schema]) -> Callable:
        schema = schemas.get(channel.schema_id)
        if schema is None or schema.name != self.schema:
            raise SourceError(f"{self.path}: topic {self._topic} changed its type to "
                              f"{_shown(_schema_name(schema)) or 'none'}", "no-topic")
        if schema.name in FOXGLOVE_IMAGE_SCHEMAS:
            if schema.encoding == "protobuf" and channel.message_encoding == "protobuf":
                return _FOXGLOVE_DECODERS[schema.name]
            raise SourceError(
                f"{self.path}: cannot decode {self._topic} (messages in "
                f"{_shown(channel.message_encoding)!r} with a {_shown(schema.encoding)!r} "
                "schema); Foxglove's images are read in protobuf", "bad-schema")
        # decoded by the type's own definition, not the bag's text: a schema named Image whose
        # text declares an array of a million one-byte structures made a Python object per
        # byte (a 1.9 KB bag took 4.9 GB); a real Image's bytes are the same either way
        ours = Schema(id=schema.id, name=schema.name, encoding="ros2msg",
                      data=(IMAGE_MSGDEF if schema.name == IMAGE
                            else COMPRESSED_IMAGE_MSGDEF).encode())
        try:
            decode = (decoders.decoder_for(channel.message_encoding, ours)
                      if schema.encoding in ("ros2msg", "ros2idl") else None)
        except Exception as exc:
            decode, why = None, f"{type(exc).__name__}: {str(exc)[:120]}"
        else:
            why = f"messages in {channel.message_encoding!r} with a {schema.encoding!r} schema"
        if decode is None:
            raise SourceError(f"{self.path}: cannot decode {self._topic} ({why}); ROS 2 bags "
                              "hold cdr messages with ros2msg schemas", "bad-schema")
        return decode

    def _decode(self, message, index: int) -> np.ndarray:
        try:
            if self.schema in RAW_SCHEMAS:
                return image_from_raw(int(message.width), int(message.height),
                                      str(message.encoding), int(message.is_bigendian),
                                      int(message.step), bytes(message.data))
            return image_from_compressed(str(message.format), bytes(message.data))
        except ImageError as exc:
            raise SourceError(f"{self.path}: {self._topic} message {index}: {exc.detail}",
                              exc.reason) from None
        except (AttributeError, TypeError, ValueError) as exc:
            raise SourceError(f"{self.path}: {self._topic} message {index} is not a "
                              f"{self.schema} ({exc})", "bad-message") from None

    def frames(self, on_error: Callable[[str, str], None] | None = None, *,
               hold_backwards: bool = False) -> Iterator[tuple[float, np.ndarray]]:
        """``(t, image)`` per message: seconds since the first frame, gray or BGR uint8.

        Parameters
        ----------
        on_error : callable(reason, message), optional
            Called for a message that cannot be used (it is skipped) and for a cut or corrupt
            file (the frames end there). Without it, these raise :class:`SourceError`, and so
            does the first frame whose header stamp goes back (a clock reset included: its
            first frame is one).
        hold_backwards : bool
            With ``on_error``: a frame whose header stamp goes back from the latest is reported
            (``stamp-backwards``) and then yielded at the latest frame's time instead of
            skipped, so that every message gives a frame and the times never go back.

        Notes
        -----
        :data:`CLOCK_RESET_FRAMES` frames in a row whose stamps go back from the latest but
        advance among themselves are a new timeline (a camera's clock reset, or a latest stamp
        far ahead): the last of them is reported to ``on_error`` as ``clock-reset`` (naming the
        message and the jump back) and yielded, ``t`` going on from the latest frame's by the
        differences of the new stamps, against whose latest the next ones are checked. The
        frames of the run before it were reported as ``stamp-backwards`` (held or skipped).

        A frame whose header stamp is unset (zero) among header stamps is timed by its log time
        where that is within MAX_FRAME_GAP_S after the latest frame's ``t``, else (and after a
        clock reset) held at the latest frame's ``t``: that frame is reported to ``on_error`` as
        ``stamp-unset`` (naming the message) and yielded. Without ``on_error`` it is yielded
        unreported: it is no error.
        """
        timeline = _Timeline(self.start_ns)
        # the message's own number in the topic (one that did not decode is counted too)
        for message, log_time, index in self._messages(on_error):
            try:
                image = self._decode(message, index)
                stamp = _stamp_ns(message) if self.clock == "header" else 0  # 0: unset
                reset = self._check_stamp(stamp, index, timeline)
            except SourceError as exc:
                if on_error is None:
                    raise
                on_error(exc.reason, str(exc))
                if hold_backwards and exc.reason == "stamp-backwards":
                    yield timeline.latest_t, image
                continue
            if reset is not None:  # the frame is kept: on_error hears of the new timeline
                on_error(CLOCK_RESET, reset)
            timeline.latest_t, unset = self._frame_t(stamp, log_time, timeline, index)
            if unset is not None and on_error is not None:  # the frame is kept, held
                on_error(STAMP_UNSET, unset)
            yield timeline.latest_t, image

    def _frame_t(self, stamp: int, log_time: int, timeline: "_Timeline",
                 index: int) -> tuple[float, str | None]:
        """A frame's ``t``: its header stamp on the timeline, or its log time (a stamp left
        unset, or a bag timed by the recorder) relative to the first frame's, never before the
        latest frame's (the recorder logs a frame when it arrives, and two may arrive swapped).
        A stamp left unset among header stamps takes its log time only within
        MAX_FRAME_GAP_S after the latest frame's ``t``, else the latest frame's: the recorder's
        clock need not be the camera's (simulated time), and after a clock reset it is not the
        new timeline's. Returns ``t`` and, for a frame held so (message ``index``), what to
        report of it (else None): a frame held at the latest frame's time, whichever clock."""
        if stamp:
            return timeline.t(stamp), None
        logged = (int(log_time) - self.start_ns) / 1e9
        if self.clock == "log":
            if logged >= timeline.latest_t:
                return logged, None
            # logged as it arrived: two frames that arrived swapped, or a file not in log-time
            # order (the frames are read in file order)
            return timeline.latest_t, (
                f"{self.path}: {self._topic} message {index}: timed by its log time (the "
                f"topic's first frame has no header stamp), and its log time is "
                f"{_seconds(timeline.latest_t - logged)} s before the latest frame's time: "
                "held at the latest frame's time")
        gap = logged - timeline.latest_t
        if timeline.rebased:
            why = "after a clock reset its log time is not on the camera's timeline"
        elif gap < 0.0:
            why = f"its log time is {_seconds(-gap)} s before the latest frame's time"
        elif gap > MAX_FRAME_GAP_S:
            why = (f"its log time is {_seconds(gap)} s after the latest frame's time (more than "
                   f"{MAX_FRAME_GAP_S:g} s)")
        else:
            return logged, None
        return timeline.latest_t, (f"{self.path}: {self._topic} message {index}: its header "
                                   f"stamp is unset (0) and {why}: held at the latest frame's "
                                   "time")

    def _check_stamp(self, stamp: int, index: int, timeline: "_Timeline") -> str | None:
        """Take a message's header stamp (ns; 0 where unset) on the timeline; SourceError where
        it goes back from the latest: a camera's clock only advances, and frames timed
        backwards would give the targets' expansion and time to contact the wrong sign. Returns
        what to report when the stamp completes a clock reset (:data:`CLOCK_RESET_FRAMES` in a
        row going back and advancing; the timeline is then re-based on them), else None. (A
        stamp left unset, zero, takes the log time instead: that is not checked.)"""
        if not stamp:
            return None
        if stamp >= timeline.latest:
            timeline.take(stamp)
            return None
        latest = timeline.latest
        if timeline.behind(stamp) < CLOCK_RESET_FRAMES:
            raise SourceError(f"{self.path}: {self._topic} message {index}: its header stamp is "
                              f"{(latest - stamp) / 1e9:g} s before an earlier frame's; a "
                              "camera's stamps never go back", "stamp-backwards")
        jump = timeline.rebase()
        return (f"{self.path}: {self._topic} message {index}: clock reset: the header stamps "
                f"went back {_seconds(jump)} s and advance again ({CLOCK_RESET_FRAMES} frames "
                "in a row; the camera's clock was reset, or the latest stamp was far ahead): "
                "timed on from the latest frame's time")


class _Timeline:
    """Where a bag's header stamps put its frames in time: ``t`` of a stamp, the latest stamp
    taken, and the frames in a row whose stamps go back from it while advancing among
    themselves (a clock reset, once :data:`CLOCK_RESET_FRAMES` long).

    Attributes
    ----------
    latest : int
        The latest header stamp taken, nanoseconds (0: none yet).
    latest_t : float
        The latest frame's ``t``.
    rebased : bool
        Whether a clock reset re-based the timeline.
    """

    def __init__(self, start_ns: int):
        self._origin_ns, self._origin_t = start_ns, 0.0  # a stamp and its t: the others follow
        self.latest, self.latest_t = 0, 0.0
        self.rebased = False
        self._run: list[int] = []  # the stamps in a row going back from latest, advancing

    def t(self, stamp: int) -> float:
        """Seconds since the first frame of a frame stamped ``stamp`` (ns) on this timeline."""
        return self._origin_t + (stamp - self._origin_ns) / 1e9

    def take(self, stamp: int) -> None:
        """A stamp at or after the latest: the latest now (a run going back ends here)."""
        self.latest = stamp
        self._run.clear()

    def behind(self, stamp: int) -> int:
        """Count a stamp before the latest: the frames of the run it makes, itself included
        (one that does not advance from the run's last starts a new run)."""
        if not (self._run and stamp > self._run[-1]):
            self._run.clear()
        self._run.append(stamp)
        return len(self._run)

    def rebase(self) -> float:
        """Make the run a new timeline: its first stamp at the latest frame's ``t`` (where the
        run's frames were held, so ``t`` does not go back), its last stamp the latest.
        Returns how far the stamps went back, in seconds."""
        first, last = self._run[0], self._run[-1]
        jump = (self.latest - first) / 1e9
        self._origin_ns, self._origin_t = first, self.latest_t
        self.latest, self.rebased = last, True
        self._run.clear()
        return jump


def _seconds(value: float) -> str:
    """Seconds to the millisecond, without trailing zeros, never in exponent notation (a
    clock reset to zero goes back some 1.7e9 s)."""
    return f"{value:.3f}".rstrip("0").rstrip(".")


def _stamp_ns(message) -> int:
    stamp = message.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def open_bag(path: str | Path, topic: str | None = None) -> BagClip:
    """Open an image topic of a ROS 2 bag (an ``.mcap`` file, or a rosbag2 directory holding
    one or, for a bag split by size or duration, several, read in the order of their numbers),
    checking that its first frame decodes.

    Raises
    ------
    SourceError
        If the bag is missing, not MCAP, cut before its first frame, has no such image topic
        (or, without ``topic``, not exactly one), or its first frame does not decode.
    """
    path = Path(path)
    if path.is_dir():
        files = bag_files(path)
        if len(files) == 1:
            return BagClip(files[0], topic)
        return BagClip(path, topic, parts=files)
    return BagClip(path, topic)


def bag_files(folder: Path) -> list[Path]:
    """The files of a rosbag2 directory, as its ``metadata.yaml`` lists them
    (``relative_file_paths``): other files beside them (a copy, a recovered file, results
    written there) are not part of the bag. A metadata file that lists none: every ``.mcap``
    in the folder, in the order of their numbers.

    Raises
    ------
    SourceError
        If the metadata cannot be read, names another storage than MCAP or a file that is
        not there, or the folder holds no ``.mcap``.
    """
    meta = folder / "metadata.yaml"
    try:
        info = (yaml.safe_load(meta.read_text(encoding="utf-8")) or {}).get(
            "rosbag2_bagfile_information") or {}
    except (OSError, UnicodeDecodeError, yaml.YAMLError, AttributeError) as exc:
        raise SourceError(f"{meta}: not a rosbag2 metadata file ({type(exc).__name__})",
                          "not-a-bag") from None
    if not isinstance(info, dict):  # a list, a string
        raise SourceError(f"{meta}: not a rosbag2 metadata file (its "
                          "rosbag2_bagfile_information is not a mapping)", "not-a-bag")
    storage = str(info.get("storage_identifier") or "mcap")
    if storage != "mcap":
        raise SourceError(f"{folder}: a bag stored in {storage}; only MCAP bags are read "
                          "(ros2 bag convert makes one)", "not-a-bag")
    listed = info.get("relative_file_paths") or []
    if not isinstance(listed, list) or not all(isinstance(p, str) for p in listed):
        raise SourceError(f"{meta}: relative_file_paths is not a list of file names",
                          "not-a-bag")
    if listed:
        # some rosbag2 versions wrote the bag's own folder name before each file's
        files = [folder / name if (folder / name).is_file() else folder / Path(name).name
                 for name in listed]
        gone = [str(p.name) for p in files if not p.is_file()]
        if gone:
            raise SourceError(f"{folder}: metadata.yaml lists {', '.join(gone)}, which "
                              f"{'is' if len(gone) == 1 else 'are'} not there", "missing")
        return files
    files = sorted((p for p in folder.iterdir() if p.suffix == ".mcap"), key=_part_order)
    if not files:
        raise SourceError(f"{folder}: a bag directory without .mcap files", "missing")
    return files


def _part_order(path: Path) -> tuple:
    """rosbag2 numbers the files of a split bag ``<name>_<n>.mcap``: n in numeric order."""
    return tuple(int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path.stem))


def write_bag(frames, path: str | Path, *, topic: str = "/camera/image_raw", fps: float = 20.0,
              start_ns: int = 1_700_000_000_000_000_000, frame_id: str = "camera",
              format: str = "raw") -> Path:
    """Write gray or BGR uint8 frames as a ROS 2 bag (MCAP) with one image topic.

    Parameters
    ----------
    frames : iterable of ndarray
    path : str or Path
        The ``.mcap`` file written.
    topic : str
    fps : float
        The header stamps advance by ``1 / fps``, from ``start_ns``.
    start_ns : int
        The first frame's header stamp and log time, nanoseconds since the epoch.
    frame_id : str
        The headers' ``frame_id``.
    format : {'raw', 'png', 'jpeg'}
        ``sensor_msgs/msg/Image`` (mono8 or bgr8) or ``sensor_msgs/msg/CompressedImage``.
    """
    if format not in ("raw", "png", "jpeg"):
        raise ValueError(f"unknown bag image format {format!r}; choose raw, png or jpeg")
    path = Path(path)
    seekable_target(path)
    with open(path, "wb") as fh, Ros2Writer(fh) as writer:
        raw = format == "raw"
        schema = register_image_type(writer, IMAGE if raw else COMPRESSED_IMAGE)
        for index, frame in enumerate(frames):
            stamp = start_ns + round(index * 1e9 / fps)
            frame = np.ascontiguousarray(frame)
            if raw:
                message = raw_image_message(frame, stamp, frame_id)
            else:
                ok, data = cv2.imencode(".png" if format == "png" else ".jpg", frame)
                if not ok:
                    raise ValueError(f"cannot encode a {frame.shape} frame as {format}")
                message = compressed_image_message(data.tobytes(), format, stamp, frame_id)
            writer.write_message(topic, schema, message, log_time=stamp, publish_time=stamp,
                                 sequence=index)
    return path


def register_image_type(writer: Ros2Writer, datatype: str):
    """The schema of ``sensor_msgs/msg/Image`` or ``CompressedImage`` in a ROS 2 MCAP writer:
    the message definition rosbag2 embeds."""
    return writer.register_msgdef(datatype, IMAGE_MSGDEF if datatype == IMAGE
                                  else COMPRESSED_IMAGE_MSGDEF)


# ROS 2 names (design.ros2.org, "Topic and Service name mapping to DDS"): each token of a name
# holds ASCII letters, digits and single underscores, does not start with a digit nor end with an
# underscore; a fully qualified topic of C characters in N tokens has C + N + 8 <= 255 (room
# for the DDS prefix, and one character per separator). rmw's validation refuses other
# characters and a token starting with a digit; the underscore rules are the article's, kept
# so that no tool that checks them refuses ours.
_ROS_PREFIX_CHARS = 8
_ROS_MAX_DDS_CHARS = 255


def ros_name_token(text: str) -> str:
    """``text`` as one token of a ROS 2 name: each run of characters other than ASCII letters
    and digits becomes one underscore, none kept at either end, and a token that would then be
    empty or start with a digit gets an ``r`` in front: ``cam-2`` -> ``cam_2``, ``_a__b-`` ->
    ``a_b``, ``7`` -> ``r7``, ``-`` -> ``r``.

    Not one to one: ``cam-2``, ``cam_2`` and ``cam--2`` give one token, as do ``7`` and ``r7``.
    """
    token = "_".join(re.findall(r"[A-Za-z0-9]+", text))
    return token if token[:1].isalpha() else "r" + token


def ros_topic(name: str) -> str:
    """The absolute ROS 2 topic of a ``/``-separated ``name`` (a Zenoh key such as
    ``asnn/cam-2/frame``): each of its parts as a token (:func:`ros_name_token`), so
    ``/asnn/cam_2/frame``.

    Raises
    ------
    ValueError
        If the topic is longer than ROS 2 allows (some 240 characters, less with many parts).
    """
    tokens = [ros_name_token(part) for part in name.strip("/").split("/")]
    topic = "/" + "/".join(tokens)
    if len(topic) + len(tokens) + _ROS_PREFIX_CHARS > _ROS_MAX_DDS_CHARS:
        shown = repr(name) if len(name) <= 80 else repr(name[:80]) + "..."
        raise ValueError(f"the ROS 2 topic of {shown} is {len(topic)} characters in "
                         f"{len(tokens)} parts, longer than ROS 2 allows (characters + parts "
                         f"<= {_ROS_MAX_DDS_CHARS - _ROS_PREFIX_CHARS})")
    return topic


def ros_time_ns(seconds: float) -> int:
    """Seconds since the epoch in nanoseconds, for a message's header stamp: 0 to the last
    second a ROS 2 ``int32`` of seconds holds."""
    return min(max(round(seconds * 1e9), 0), (2**31 - 1) * 1_000_000_000)


def _header(stamp_ns: int, frame_id: str) -> dict:
    return {"stamp": {"sec": stamp_ns // 1_000_000_000, "nanosec": stamp_ns % 1_000_000_000},
            "frame_id": frame_id}


def raw_image_message(image: np.ndarray, stamp_ns: int, frame_id: str = "camera") -> dict:
    """A gray (mono8) or BGR (bgr8) uint8 picture as a ``sensor_msgs/msg/Image``, stamped
    ``stamp_ns`` (nanoseconds since the epoch), for :class:`mcap_ros2.writer.Writer`."""
    gray = image.ndim == 2
    return {"header": _header(stamp_ns, frame_id), "height": image.shape[0],
            "width": image.shape[1], "encoding": "mono8" if gray else "bgr8", "is_bigendian": 0,
            "step": image.shape[1] * (1 if gray else 3),
            "data": np.ascontiguousarray(image).tobytes()}


def compressed_image_message(data: bytes, format: str, stamp_ns: int,
                             frame_id: str = "camera") -> dict:
    """An encoded picture (``format``: jpeg or png) as a ``sensor_msgs/msg/CompressedImage``,
    stamped ``stamp_ns`` (nanoseconds since the epoch), for :class:`mcap_ros2.writer.Writer`."""
    return {"header": _header(stamp_ns, frame_id), "format": format, "data": bytes(data)}
