"""Foxglove's image messages in an MCAP file: ``foxglove.CompressedImage`` and
``foxglove.RawImage``, decoded from protobuf by their published field numbers.

Foxglove's own recorders, its SDKs and ``asnn detect --mcap`` write camera pictures in these
schemas rather than as ROS 2 messages. They are read here without a protobuf library and without
the schema the file embeds: the two messages' field numbers are fixed by Foxglove's published
``.proto`` files, so a file's schema text cannot make the reader build anything (as with the
ROS 2 types, :mod:`asnn.io.rosbag` decodes by the type's own definition). A message is at most
:data:`~asnn.io.mcap_reader.MAX_MESSAGE_BYTES` before it gets here; decoding it allocates no more
than its own size again, and reads at most :data:`_MAX_FIELDS` fields (a message of millions of
tiny unknown fields took minutes of Python each). A ``timestamp`` must fit nanoseconds in 64
bits (before the year 2262).

The decoded message looks like the ROS 2 one the bag reader already handles: a ``header`` with
``stamp.sec``, ``stamp.nanosec`` and ``frame_id``, then ``format`` and ``data``
(CompressedImage) or ``width``, ``height``, ``encoding``, ``step``, ``is_bigendian`` (always 0:
Foxglove's raw images carry no byte-order field) and ``data`` (RawImage). A field the message
leaves out reads as protobuf's default (zero, empty), so a message without a timestamp is an
unset stamp, timed by the recorder's log time as a ROS 2 frame stamped zero is.

References
----------
.. [1] Foxglove, "CompressedImage" and "RawImage" message schemas,
   https://docs.foxglove.dev/docs/visualization/message-schemas/
.. [2] Protocol Buffers, "Encoding", https://protobuf.dev/programming-guides/encoding/
"""

from __future__ import annotations

import codecs
from types import SimpleNamespace

__all__ = ["FOXGLOVE_COMPRESSED_IMAGE", "FOXGLOVE_RAW_IMAGE", "FOXGLOVE_IMAGE_SCHEMAS",
           "ProtobufError", "decode_compressed_image", "decode_raw_image"]

FOXGLOVE_COMPRESSED_IMAGE = "foxglove.CompressedImage"
FOXGLOVE_RAW_IMAGE = "foxglove.RawImage"
FOXGLOVE_IMAGE_SCHEMAS = (FOXGLOVE_COMPRESSED_IMAGE, FOXGLOVE_RAW_IMAGE)

# protobuf wire types
_VARINT, _FIXED64, _BYTES, _FIXED32 = 0, 1, 2, 5
_MAX_VARINT_BYTES = 10
_MAX_FIELDS = 256  # fields read in one message (Foxglove's images have 7, a Timestamp 2)
_MAX_SECONDS = (1 << 63) // 1_000_000_000  # stamps in int64 nanoseconds (the year 2262)
_MAX_TEXT = 4096  # characters kept of a frame_id, format or encoding (names, not payloads)

# (field number, wire type) of each field the reader takes, by message
_TIMESTAMP = {1: ("seconds", _VARINT), 2: ("nanos", _VARINT)}
_COMPRESSED = {1: ("timestamp", _BYTES), 2: ("data", _BYTES), 3: ("format", _BYTES),
               4: ("frame_id", _BYTES)}
_RAW = {1: ("timestamp", _BYTES), 2: ("width", _FIXED32), 3: ("height", _FIXED32),
        4: ("encoding", _BYTES), 5: ("step", _FIXED32), 6: ("data", _BYTES),
        7: ("frame_id", _BYTES)}


class ProtobufError(ValueError):
    """Bytes that are not a message of the expected type: cut short, a field of the wrong wire
    type, a group (protobuf's deprecated form), or text that is not UTF-8."""


def _varint(data: memoryview, at: int) -> tuple[int, int]:
    """The unsigned varint at ``at`` and the offset after it."""
    value, shift = 0, 0
    for k in range(_MAX_VARINT_BYTES):
        if at + k >= len(data):
            raise ProtobufError("a varint is cut short")
        byte = data[at + k]
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            return value, at + k + 1
        shift += 7
    raise ProtobufError(f"a varint longer than {_MAX_VARINT_BYTES} bytes")


def _fields(data, known: dict) -> dict:
    """The known fields of one message (the last occurrence of each, as protobuf merges a
    repeated scalar), by name; unknown fields are skipped by their wire type."""
    data = memoryview(data)
    found: dict = {}
    at, count = 0, 0
    while at < len(data):
        count += 1
        if count > _MAX_FIELDS:  # a picture's message has 7 fields: this is no such message
            raise ProtobufError(f"more than {_MAX_FIELDS} fields")
        key, at = _varint(data, at)
        number, wire = key >> 3, key & 7
        if wire == _VARINT:
            value, at = _varint(data, at)
        elif wire == _FIXED64:
            value, at = data[at:at + 8], at + 8
        elif wire == _FIXED32:
            value, at = data[at:at + 4], at + 4
        elif wire == _BYTES:
            length, at = _varint(data, at)
            value, at = data[at:at + length], at + length
        else:
            raise ProtobufError(f"field {number} has wire type {wire} (groups are not read)")
        if at > len(data):
            raise ProtobufError(f"field {number} is cut short")
        if number in known:
            name, expected = known[number]
            if wire != expected:
                raise ProtobufError(f"field {number} ({name}) has wire type {wire}, "
                                    f"not {expected}")
            found[name] = value
    return found


def _text(value) -> str:
    """A string field's first :data:`_MAX_TEXT` characters (a character cut by the limit is
    left out, not an error)."""
    if value is None:
        return ""
    try:
        return codecs.getincrementaldecoder("utf-8")().decode(
            bytes(value[:4 * _MAX_TEXT]), final=len(value) <= 4 * _MAX_TEXT)[:_MAX_TEXT]
    except UnicodeDecodeError as exc:
        raise ProtobufError(f"a text field is not UTF-8 ({exc.reason})") from None


def _uint32(value) -> int:
    return 0 if value is None else int.from_bytes(value, "little")


def _header(found: dict) -> SimpleNamespace:
    """``header.stamp.sec``, ``header.stamp.nanosec`` and ``header.frame_id`` from a message's
    ``timestamp`` (a google.protobuf.Timestamp) and ``frame_id``."""
    stamp = _fields(found.get("timestamp", b""), _TIMESTAMP)
    seconds = stamp.get("seconds", 0)
    if seconds >= 1 << 63:  # int64 on the wire as two's complement
        seconds -= 1 << 64
    nanos = stamp.get("nanos", 0) & 0xFFFFFFFF
    if nanos >= 1 << 31:
        nanos -= 1 << 32
    if not 0 <= nanos < 1_000_000_000:
        raise ProtobufError(f"timestamp nanos {nanos} is outside 0..999999999")
    if not 0 <= seconds < _MAX_SECONDS:  # nanoseconds since 1970 must fit an int64
        raise ProtobufError(f"timestamp seconds {seconds} is outside 0..{_MAX_SECONDS - 1}")
    return SimpleNamespace(stamp=SimpleNamespace(sec=seconds, nanosec=nanos),
                           frame_id=_text(found.get("frame_id")))


def decode_compressed_image(data: bytes) -> SimpleNamespace:
    """A ``foxglove.CompressedImage`` in protobuf as ``header``, ``format`` and ``data``.

    Parameters
    ----------
    data : bytes-like
        One message's bytes.

    Returns
    -------
    SimpleNamespace
        ``header`` (``stamp.sec``, ``stamp.nanosec``, ``frame_id``), ``format`` (str) and
        ``data`` (a view of the picture's bytes within ``data``).

    Raises
    ------
    ProtobufError
        For bytes that are not such a message.
    """
    found = _fields(data, _COMPRESSED)
    return SimpleNamespace(header=_header(found), format=_text(found.get("format")),
                           data=found.get("data", b""))


def decode_raw_image(data: bytes) -> SimpleNamespace:
    """A ``foxglove.RawImage`` in protobuf as the fields of a ``sensor_msgs/msg/Image``.

    Parameters
    ----------
    data : bytes-like
        One message's bytes.

    Returns
    -------
    SimpleNamespace
        ``header`` (``stamp.sec``, ``stamp.nanosec``, ``frame_id``), ``width``, ``height``,
        ``encoding``, ``step``, ``is_bigendian`` (0) and ``data`` (a view of the pixels within
        ``data``): what :func:`asnn.io.rosbag.image_from_raw` takes.

    Raises
    ------
    ProtobufError
        For bytes that are not such a message.
    """
    found = _fields(data, _RAW)
    return SimpleNamespace(header=_header(found), width=_uint32(found.get("width")),
                           height=_uint32(found.get("height")),
                           encoding=_text(found.get("encoding")), step=_uint32(found.get("step")),
                           is_bigendian=0, data=found.get("data", b""))
