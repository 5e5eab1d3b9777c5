"""A detector's output for Foxglove: messages in Foxglove's published schemas, and an MCAP file
of them (``asnn detect ... --mcap OUT.mcap``).

Uses the Foxglove SDK (``foxglove-sdk``, the optional ``ros`` extra): its channels carry the
schemas (``foxglove.CompressedImage``, ``foxglove.ImageAnnotations``, protobuf) and its writer
makes MCAP files that the Foxglove app opens with no set-up. The message builders here are shared
with the live server (``clients/foxglove.py``), so a layout made for a recorded run shows the
fleet too. Topics and fields: docs/foxglove.md.

Targets are the dicts of ``Target.to_dict()`` (x, y, direction, energy, pixels), with the
optional ``id`` and ``ttc`` drawn where present.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .files import RecordingFile
from .images import ENCODED_FORMATS, encode
from .visualize import target_arrow, target_label

try:
    import foxglove
    from foxglove.channels import CompressedImageChannel, ImageAnnotationsChannel
    from foxglove.messages import (CircleAnnotation, Color, CompressedImage, ImageAnnotations,
                                   KeyValuePair, Point2, PointsAnnotation,
                                   PointsAnnotationType, TextAnnotation, Timestamp)
except ImportError as exc:  # the optional extra is missing: say which one, in one line
    raise ImportError("Foxglove output needs the 'ros' extra: pip install 'asnn[ros]'"
                      f" ({exc.name} is missing)") from exc

__all__ = ["DEFAULT_TOPIC_PREFIX", "IMAGE_FORMATS", "RESPONSE_SCHEMA", "FoxgloveMcapWriter",
           "McapRecording", "close_channels", "image_message", "response_message",
           "target_annotations", "time_ns", "timestamp"]

DEFAULT_TOPIC_PREFIX = "/asnn"
IMAGE_FORMATS = ENCODED_FORMATS
TARGET_COLOR = Color(r=0.0, g=0.31, b=1.0, a=1.0)   # the blue of the annotated videos
WARNING_COLOR = Color(r=1.0, g=0.0, b=0.0, a=1.0)
LABEL_BACKGROUND = Color(r=1.0, g=1.0, b=1.0, a=0.7)
TARGET_MARK = 7.0  # diameter of a target's dot, picture pixels

_NUMBER, _INTEGER = {"type": "number"}, {"type": "integer"}
_TIME = {"type": "object", "description": "the frame's time (header stamp of a bag, capture "
         "time of a camera)", "properties": {"sec": _INTEGER, "nsec": _INTEGER}}
_TARGET = {"type": "object", "properties": {
    "x": _NUMBER, "y": _NUMBER, "direction": _NUMBER, "energy": _NUMBER, "pixels": _INTEGER,
    "id": {"type": ["integer", "null"]}, "expansion": {"type": ["number", "null"]},
    "ttc": {"type": ["number", "null"]}, "offset": {"type": ["number", "null"]},
    "approaching": {"type": ["boolean", "null"]}}}
RESPONSE_SCHEMA = {
    "title": "asnn.Response",
    "description": "The detector's response to one frame (CONTRACT.md): asnn detect's record, "
                   "or the service's Response of a robot",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame": {**_INTEGER, "description": "0-based frame index (asnn detect)"},
        "t": {**_NUMBER, "description": "seconds since the first frame (asnn detect)"},
        "v": {**_INTEGER, "description": "wire format version (the service's Response)"},
        "robot": {"type": "string"}, "seq": _INTEGER, "stamp": _NUMBER,
        "u": _NUMBER, "out": _NUMBER, "spikes": _INTEGER, "spike_rate": _NUMBER,
        "collision": {"type": "boolean"},
        "targets": {"type": "array", "items": _TARGET},
        "model": {"type": "string"}, "preset": {"type": "string"}, "worker": {"type": "string"},
        "latency_ms": _NUMBER, "dropped": _INTEGER, "model_ms": {"type": ["number", "null"]},
        "stream_frames": {"type": ["integer", "null"]},
    },
}


MAX_TIME_NS = (2**32 - 1) * 1_000_000_000  # Foxglove times count unsigned 32-bit seconds


def time_ns(seconds: float) -> int:
    """Nanoseconds since the epoch from seconds, clamped to the times Foxglove represents."""
    seconds = float(seconds)
    if math.isnan(seconds):
        return 0
    return min(int(min(max(seconds, 0.0), MAX_TIME_NS / 1e9) * 1e9), MAX_TIME_NS)


def timestamp(ns: int) -> Timestamp:
    """A Foxglove time from nanoseconds since the epoch (clamped to its range)."""
    ns = min(max(int(ns), 0), MAX_TIME_NS)
    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def image_message(image: np.ndarray, stamp_ns: int, *, frame_id: str = "camera",
                  format: str = "jpeg") -> CompressedImage:
    """A gray or BGR uint8 frame as a ``foxglove.CompressedImage`` (jpeg, or png: lossless)."""
    return CompressedImage(timestamp=timestamp(stamp_ns), frame_id=frame_id,
                           data=encode(image, format), format=format)


def target_annotations(targets: Sequence[Mapping], stamp_ns: int, size: tuple[int, int], *,
                       collision: bool = False, scale: tuple[float, float] = (1.0, 1.0)
                       ) -> ImageAnnotations:
    """A frame's targets as a ``foxglove.ImageAnnotations``.

    Each target is a dot at its position with an arrow along its direction, longer for more
    motion energy (as in the annotated videos and the paper's Fig. 12), and, where the target has
    an ``id`` or a ``ttc``, a label (``#3 ttc 1.2 s``); every field of the target is in the
    dot's metadata. A red border
    frames the picture while the warning is on.

    Parameters
    ----------
    targets : sequence of mapping
        ``x``, ``y``, ``direction``, ``energy``, ``pixels``; optional ``id``, ``ttc``.
    stamp_ns : int
        The frame's time, so that Foxglove pairs the annotations with their image.
    size : (width, height)
        Of the picture the annotations are drawn on.
    collision : bool
    scale : (sx, sy)
        From the frame's pixels (the targets' coordinates) to the picture's, e.g. a thumbnail.
    """
    stamp = timestamp(stamp_ns)
    sx, sy = scale
    width, height = size
    circles, points, texts = [], [], []
    for target in targets:
        x, y = float(target["x"]), float(target["y"])
        tip_x, tip_y = target_arrow(x, y, float(target["direction"]), float(target["energy"]),
                                    (height / sy, width / sx))
        circles.append(CircleAnnotation(
            timestamp=stamp, position=Point2(x=x * sx, y=y * sy), diameter=TARGET_MARK,
            thickness=2.0, outline_color=TARGET_COLOR, fill_color=TARGET_COLOR,
            metadata=[KeyValuePair(key=str(k), value=str(v)) for k, v in target.items()]))
        points.append(PointsAnnotation(
            timestamp=stamp, type=PointsAnnotationType.LineList, thickness=2.0,
            points=_arrow(x * sx, y * sy, tip_x * sx, tip_y * sy), outline_color=TARGET_COLOR))
        label = target_label(dict(target))
        if label:
            texts.append(TextAnnotation(
                timestamp=stamp, position=Point2(x=x * sx + TARGET_MARK, y=y * sy), text=label,
                font_size=12.0, text_color=TARGET_COLOR, background_color=LABEL_BACKGROUND))
    if collision:
        corners = [(0.5, 0.5), (width - 0.5, 0.5), (width - 0.5, height - 0.5),
                   (0.5, height - 0.5)]
        points.append(PointsAnnotation(
            timestamp=stamp, type=PointsAnnotationType.LineLoop, thickness=3.0,
            points=[Point2(x=px, y=py) for px, py in corners], outline_color=WARNING_COLOR))
    return ImageAnnotations(timestamp=stamp, circles=circles, points=points, texts=texts)


def _arrow(x: float, y: float, tip_x: float, tip_y: float) -> list[Point2]:
    """A LineList arrow: the shaft, and two barbs from the tip, back at +-30 degrees, 30% of the
    shaft long."""
    dx, dy = x - tip_x, y - tip_y
    tip = Point2(x=tip_x, y=tip_y)
    points = [Point2(x=x, y=y), tip]
    for turn in (math.pi / 6, -math.pi / 6):
        c, s = math.cos(turn), math.sin(turn)
        points += [tip, Point2(x=tip_x + 0.3 * (c * dx - s * dy),
                               y=tip_y + 0.3 * (s * dx + c * dy))]
    return points


def response_message(fields: Mapping, stamp_ns: int) -> dict:
    """A response's fields as the ``asnn.Response`` JSON message (:data:`RESPONSE_SCHEMA`),
    with the frame's time as ``timestamp``; non-finite numbers become null."""
    stamp = timestamp(stamp_ns)
    message = {"timestamp": {"sec": stamp.sec, "nsec": stamp.nsec}}
    for key, value in fields.items():
        message[key] = _plain(value)
    return message


def _plain(value):
    """JSON-ready: numpy scalars to Python ones, non-finite floats to None, recursively."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


# the SDK's logger of a message it could not write: one line for each after the first failure
_SDK_LOGGER = "foxglove.log_sink_set"


class _QuietAfterFailure(logging.Filter):
    """Drops the SDK's complaints once a sink has failed: the writer says it in one error."""

    def __init__(self, sink: RecordingFile):
        super().__init__()
        self._sink = sink

    def filter(self, record: logging.LogRecord) -> bool:
        return self._sink.error is None


class McapRecording:
    """An MCAP file recording every channel of a Foxglove context as it is logged (the live
    server's, ``asnn foxglove --mcap``), until :meth:`close`.

    The file must not exist (a recording is never overwritten) unless ``overwrite``. The SDK
    reports no write error to the code that logs: :attr:`error` keeps the first (a full disk),
    and :attr:`size` is the bytes written so far, for the caller to stop the recording at a
    bound of its own.

    Raises
    ------
    OSError
        If the file exists (without ``overwrite``) or cannot be created.
    """

    def __init__(self, path: str | Path, context: foxglove.Context, *,
                 overwrite: bool = False):
        self.path = Path(path)
        self._sink = RecordingFile(self.path, overwrite=overwrite)
        try:
            self._writer = foxglove.open_mcap(self._sink, context=context)
        except Exception as exc:  # the SDK's own error type
            self._sink.close()
            raise OSError(f"cannot write {self.path}: {exc}") from None
        self._quiet = _QuietAfterFailure(self._sink)
        logging.getLogger(_SDK_LOGGER).addFilter(self._quiet)

    @property
    def size(self) -> int:
        """Bytes written so far (the file's, once closed)."""
        return self._sink.tell() if self._writer is not None else self._size

    @property
    def error(self) -> OSError | None:
        """The first write that failed, or None."""
        return self._sink.error

    @property
    def closed(self) -> bool:
        return self._writer is None

    def close(self) -> OSError | None:
        """Finish the file (its index and summary) and stop recording; returns the first error
        the file met, or None. Closing twice does nothing."""
        if self._writer is None:
            return self._sink.error
        writer, failure = self._writer, None
        try:
            writer.close()
        except Exception as exc:  # the SDK's error type (RuntimeError)
            failure = exc
        finally:
            self._size = self._sink.tell()
            self._writer = None
            self._sink.close()
            logging.getLogger(_SDK_LOGGER).removeFilter(self._quiet)
        if self._sink.error is None and failure is not None:
            return OSError(str(failure))
        return self._sink.error


def close_channels(*channels) -> None:
    """Close Foxglove channels and let them go: foxglove-sdk (0.30) keeps every
    ``foxglove.Channel`` made (a JSON one: the responses and warnings) in a table of its own
    for good, with its schema, and ``close()`` leaves it there: some 2.4 kB a channel, which a
    live server whose robots come and go gathered without end."""
    import foxglove.channel

    table = getattr(foxglove.channel, "_channels_by_id", None)
    for channel in channels:
        channel.close()
        if isinstance(table, dict) and table.get(channel.id()) is channel:
            del table[channel.id()]


class FoxgloveMcapWriter:
    """Writes a detector's frames and responses to an MCAP file for Foxglove.

    Topics (``prefix`` default ``/asnn``): ``<prefix>/image`` (``foxglove.CompressedImage``),
    ``<prefix>/annotations`` (``foxglove.ImageAnnotations``), ``<prefix>/response`` (JSON
    ``asnn.Response``, every frame) and ``<prefix>/warning`` (the same, only for frames with a
    collision warning, like the service's warning key). Every message is logged at the frame's
    time and carries it as its ``timestamp``.

    Use as a context manager (or call ``close``): the file is complete only when closed.

    Raises
    ------
    OSError
        If the file cannot be created; from :meth:`write`, at the first frame the file could
        not take (a full disk), and from :meth:`close`, if the file cannot be finished.
    """

    def __init__(self, path: str | Path, *, prefix: str = DEFAULT_TOPIC_PREFIX,
                 frame_id: str = "camera", image_format: str = "jpeg"):
        if image_format not in IMAGE_FORMATS:
            raise ValueError(f"unknown image format {image_format!r}")
        self.path = Path(path)
        self.frame_id = frame_id or "camera"
        self.image_format = image_format
        self._context = foxglove.Context()  # only this file's channels reach this writer
        self._recording = McapRecording(self.path, self._context, overwrite=True)
        self._failed = False
        prefix = prefix.rstrip("/")
        self.topics = {kind: f"{prefix}/{kind}"
                       for kind in ("image", "annotations", "response", "warning")}
        self._image = CompressedImageChannel(self.topics["image"], context=self._context)
        self._annotations = ImageAnnotationsChannel(self.topics["annotations"],
                                                    context=self._context)
        self._response = foxglove.Channel(self.topics["response"], schema=RESPONSE_SCHEMA,
                                          context=self._context)
        self._warning = foxglove.Channel(self.topics["warning"], schema=RESPONSE_SCHEMA,
                                         context=self._context)
        self.written = 0

    def write(self, image: np.ndarray, record: Mapping, stamp_ns: int) -> None:
        """One frame and its response record (the ``asnn detect --jsonl`` fields)."""
        stamp_ns = min(max(int(stamp_ns), 0), MAX_TIME_NS)
        height, width = image.shape[:2]
        self._image.log(image_message(image, stamp_ns, frame_id=self.frame_id,
                                      format=self.image_format), log_time=stamp_ns)
        self._annotations.log(target_annotations(record.get("targets", ()), stamp_ns,
                                                 (width, height),
                                                 collision=bool(record.get("collision"))),
                              log_time=stamp_ns)
        message = response_message(record, stamp_ns)
        self._response.log(message, log_time=stamp_ns)
        if record.get("collision"):
            self._warning.log(message, log_time=stamp_ns)
        error = self._recording.error
        if error is not None:
            self._failed = True
            raise OSError(f"cannot write {self.path}: {error.strerror or error}")
        self.written += 1

    def close(self) -> None:
        """Finish the file (its index and summary); after a failed :meth:`write`, which said
        why, only let it go.

        Raises
        ------
        OSError
            If the file cannot be finished (a full disk).
        """
        if self._recording.closed:
            return
        try:
            error = self._recording.close()
        finally:
            close_channels(self._image, self._annotations, self._response, self._warning)
        if error is not None and not self._failed:
            raise OSError(f"cannot write {self.path}: {error.strerror or error}")

    def __enter__(self) -> FoxgloveMcapWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
