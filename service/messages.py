"""Wire formats of the service, in one place: pydantic models and their msgpack codec.

All payloads are msgpack maps (CONTRACT.md). Unknown fields are ignored; a missing or ill-typed
required field makes the message invalid. Decoding raises :class:`MessageError`, whose ``reason``
is a short stable label that receivers count (REASONS; docs/operations.md):

``oversized``            payload larger than MAX_PAYLOAD bytes (checked before anything else)
``undecodable``          not msgpack
``not-a-map``            msgpack, but not a map
``unsupported-version``  ``v`` is not 1
``missing-field``        a required field is absent
``invalid-field``        a field of the wrong type or out of range (e.g. ``seq`` < 0)
``bad-stamp``            ``stamp`` NaN, infinite or not a number
``bad-size``             ``width`` or ``height`` not an int in 1..MAX_SIDE (4096)
``bad-format``           ``format`` not one of FORMATS
``bad-pixels``           raw data length is not width x height x channels, or an encoded image
                         of another size than the message says
``bad-image``            jpeg/png data that does not decode to an 8-bit image, or whose header
                         already shows it cannot be a whole image of its size (see below)
``bad-key``              a message on a key it does not belong to (a refusal naming another
                         robot than its key's; receivers count keys off the scheme so too)

Bounds on what a message makes a receiver allocate (docs/operations.md, "Hostile input"):

* msgpack: a map may have at most MAX_MAP_LEN entries, an array MAX_ARRAY_LEN items, a string
  MAX_STR_LEN bytes, and a whole message at most MAX_ITEMS container entries in all, counted
  on the containers' headers before msgpack reads any, so an 8-million-entry map (under
  MAX_PAYLOAD), or a thousand nested headers of arrays that never complete, is refused
  (``undecodable``), not built;
* jpeg/png: the header is read before anything is decoded (:mod:`asnn.io.images`, shared with
  the ROS 2 bag reader). Its size must be the message's, the file must be an 8-bit image of a
  kind cameras make (baseline or progressive Huffman jpeg; png of bit depth <= 8), and it must
  be long enough to hold that many pixels at the best compression its coding allows
  (:func:`asnn.io.images.min_encoded_bytes`): a truncated file whose header declares
  4096x4096 is refused before the decoder allocates 48 MiB for it and the worker a model state
  of 0.9 GB.
"""

from __future__ import annotations

import math
from typing import Any, Literal, get_args

import msgpack
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from asnn.io import images
from asnn.io.images import MAX_SIDE, ImageError, check_encoded, decode_encoded, encoded_size

from . import keys

__all__ = ["FORMATS", "Frame", "MAX_ITEMS", "MAX_PAYLOAD", "MAX_SIDE", "MessageError", "REASONS",
           "Refusal", "Response", "TargetMsg", "VERSION", "decode_frame", "decode_refusal",
           "decode_response", "decode_status", "encode", "encode_image", "encode_status",
           "encoded_size", "track_id_base", "track_label", "unpack_map"]

VERSION = 1
FrameFormat = Literal["gray8", "bgr8", "jpeg", "png"]
FORMATS = get_args(FrameFormat)
# the largest valid frame (4096 x 4096 bgr8) plus room for the other fields
MAX_PAYLOAD = MAX_SIDE * MAX_SIDE * 3 + 64 * 1024
# msgpack bounds: a frame has 7 fields, a response 17 and up to one map per looming target
MAX_MAP_LEN = 256
MAX_ARRAY_LEN = 4096
MAX_ITEMS = 16384  # container entries (map pairs and array items) in one message, in all
MAX_STR_LEN = 64 * 1024
MAX_EXT_LEN = 64
MAX_NOTE_LEN = 200  # characters of a refusal's detail and worker id
MAX_REASON_LEN = 64  # characters of a refusal's reason
MAX_REFUSAL_BYTES = 4096
REASONS = ("oversized", "undecodable", "not-a-map", "unsupported-version", "missing-field",
           "invalid-field", "bad-stamp", "bad-size", "bad-format", "bad-pixels", "bad-image",
           "bad-key")


class MessageError(ValueError):
    """An invalid message. ``reason`` is a short label for counting, ``str()`` the details."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


class _Message(BaseModel):
    # strict: "12" is not an int, 1.5 is not an int, true is not an int; extra fields ignored;
    # no protected namespace (pydantic before 2.10 warned of Response.model_ms on every start)
    model_config = ConfigDict(strict=True, extra="ignore", allow_inf_nan=False, frozen=True,
                              protected_namespaces=())


class Frame(_Message):
    """One camera frame, ``<prefix>/<robot>/frame``."""

    v: int = Field(VERSION, description="message version (1)")
    seq: int = Field(ge=0, description="increasing per robot")
    stamp: float = Field(description="capture time, seconds, camera clock")
    width: int = Field(ge=1, le=MAX_SIDE)
    height: int = Field(ge=1, le=MAX_SIDE)
    format: FrameFormat
    data: bytes = Field(description="row-major pixels (gray8, bgr8) or the encoded file")

    def image(self) -> np.ndarray:
        """The pixels: (H, W) uint8 for gray8, (H, W, 3) BGR uint8 otherwise.

        Raises
        ------
        MessageError
            ``bad-pixels`` when the data does not hold a ``width`` x ``height`` image,
            ``bad-image`` when encoded data is not a whole 8-bit image (as :meth:`check_size`)
            or does not decode.
        """
        w, h = self.width, self.height
        if self.format in ("gray8", "bgr8"):
            self.check_size()
            pixels = np.frombuffer(self.data, dtype=np.uint8)
            return pixels.reshape((h, w) if self.format == "gray8" else (h, w, 3))
        try:  # the header first: a lying or hostile size is refused before any pixel is decoded
            return decode_encoded(self.data, self.format, (w, h))
        except ImageError as exc:
            raise _message_error(exc) from None

    def check_size(self) -> None:
        """Cheap checks of the data without decoding it: a raw frame's length, an encoded
        frame's header (:func:`asnn.io.images.check_encoded`).

        Raises
        ------
        MessageError
            ``bad-pixels`` when a gray8 or bgr8 frame's data is not width x height pixels, or
            an encoded image's header gives another size; ``bad-image`` when an encoded image
            cannot be a whole 8-bit image of that size.
        """
        if self.format in ("gray8", "bgr8"):
            need = self.width * self.height * (1 if self.format == "gray8" else 3)
            if len(self.data) != need:
                raise MessageError("bad-pixels", f"{self.format} {self.width}x{self.height} "
                                   f"needs {need} bytes, got {len(self.data)}")
        else:
            try:
                check_encoded(self.data, self.format, (self.width, self.height))
            except ImageError as exc:
                raise _message_error(exc) from None

    @classmethod
    def from_image(cls, image: np.ndarray, *, seq: int, stamp: float,
                   format: str = "gray8") -> Frame:
        """Build a frame from a gray (H, W) or BGR (H, W, 3) uint8 image."""
        return cls(seq=seq, stamp=stamp, width=image.shape[1], height=image.shape[0],
                   format=format, data=encode_image(image, format))


class TargetMsg(_Message):
    """A looming region (as in ``asnn detect``); the tracked presets' optional fields
    (docs/contract.md) are left out of the payload where the model does not set them."""

    x: float
    y: float
    direction: float
    energy: float
    pixels: int = Field(ge=0)
    id: int | None = Field(None, ge=0)
    expansion: float | None = None
    ttc: float | None = Field(None, gt=0)
    offset: float | None = Field(None, ge=0)
    approaching: bool | None = None


class Response(_Message):
    """The worker's output for one frame, ``<prefix>/<robot>/response`` and ``.../warning``."""

    v: int = VERSION
    robot: str
    seq: int = Field(ge=0)
    stamp: float
    # any length CONTRACT.md allows (a worker of another team may name itself at length): the
    # fleet viewers keep at most MAX_NOTE_LEN characters of each (clients.fleet), so that 64 KiB
    # strings from 1,000 robot ids cannot hold 380 MB in the dashboard as they did
    model: str
    preset: str
    u: float
    out: float
    spikes: int = Field(ge=0)  # counts and rates: a negative one is no model's output
    spike_rate: float = Field(ge=0)
    collision: bool
    targets: list[TargetMsg]
    worker: str
    latency_ms: float = Field(ge=0)
    dropped: int = Field(ge=0)
    # optional extensions (docs/contract.md): the model step's own share of latency_ms, and
    # the frames the robot's model has stepped in its current stream (1: this one only primed it)
    model_ms: float | None = Field(default=None, ge=0)
    stream_frames: int | None = Field(default=None, ge=1)


def _message_error(exc: ImageError) -> MessageError:
    """An encoded image's refusal as a message's: a size other than the message's (or out of
    range) is ``bad-pixels``, anything else ``bad-image``."""
    return MessageError("bad-pixels" if exc.reason == "bad-size" else "bad-image", exc.detail)


def encode_image(image: np.ndarray, format: str) -> bytes:
    """Pixels of a gray or BGR uint8 image as a frame's ``data`` in ``format``."""
    if image.dtype != np.uint8 or image.ndim not in (2, 3):
        raise ValueError(f"need a uint8 gray or BGR image, got {image.dtype} {image.shape}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    import cv2  # OpenCV where pixels are: ``asnn status`` and ``alerts`` touch none

    if format == "gray8":
        gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        return np.ascontiguousarray(gray).tobytes()
    if format == "bgr8":
        bgr = image if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        return np.ascontiguousarray(bgr).tobytes()
    if format in ("jpeg", "png"):
        return images.encode(image, format)
    raise ValueError(f"unknown frame format {format!r}; choose one of {', '.join(FORMATS)}")


def encode(message: BaseModel) -> bytes:
    """msgpack bytes of a message; optional fields that are not set (None) are left out."""
    return msgpack.packb(message.model_dump(exclude_none=True), use_bin_type=True)


class _TooManyItems(ValueError):
    pass


def _msgpack_layout() -> tuple[tuple[int, ...], dict[int, tuple[str, int, int]]]:
    """How :func:`_declared_entries` steps over each msgpack type byte: the bytes a scalar
    takes in all (its type byte included) by type byte, 0 for the others; and for those,
    ``(kind, width, extra)``: a str, bin or ext (``"sized"``) whose length is ``width`` bytes,
    followed by ``extra`` bytes before its body, or a container (``"array"``, ``"map"``) whose
    count is ``width`` bytes (0: in the type byte itself)."""
    fixed = [0] * 256
    sized: dict[int, tuple[str, int, int]] = {}
    for b in range(256):
        if b < 0x80 or b >= 0xe0:  # fixint
            fixed[b] = 1
        elif b < 0x90:
            sized[b] = ("map", 0, 0)
        elif b < 0xa0:
            sized[b] = ("array", 0, 0)
        elif b < 0xc0:  # fixstr
            fixed[b] = 1 + (b & 0x1f)
    # nil, (never used), false, true, float 32/64, uint 8-64, int 8-64, fixext 1-16
    for b, size in zip([0xc0, 0xc1, 0xc2, 0xc3, 0xca, 0xcb, *range(0xcc, 0xd9)],
                       [1, 1, 1, 1, 5, 9, 2, 3, 5, 9, 2, 3, 5, 9, 3, 4, 6, 10, 18]):
        fixed[b] = size
    for b, width in ((0xc4, 1), (0xc5, 2), (0xc6, 4), (0xd9, 1), (0xda, 2), (0xdb, 4)):
        sized[b] = ("sized", width, 0)  # bin, str
    for b, width in ((0xc7, 1), (0xc8, 2), (0xc9, 4)):
        sized[b] = ("sized", width, 1)  # ext: its type byte
    for b, width in ((0xdc, 2), (0xdd, 4)):
        sized[b] = ("array", width, 0)
    for b, width in ((0xde, 2), (0xdf, 4)):
        sized[b] = ("map", width, 0)
    return tuple(fixed), sized


_FIXED_SIZE, _SIZED = _msgpack_layout()


def _declared_entries(payload: bytes, max_items: int) -> None:
    """Walk the msgpack headers of ``payload`` (skipping every string's and binary's body) and
    refuse it where its containers declare more than ``max_items`` entries in all (each
    container counting its entries plus one, map pairs as one entry): :class:`_TooManyItems`.

    msgpack allocates a container's slots when it reads its header, before its entries are
    read, and its nesting goes 1024 deep: 1023 array headers of 4,096 items (3 KB) took 32 MiB
    and 27 ms of unpacking before the payload was found to end there. Counted here, at the
    headers, before anything is built, the slots of everything msgpack may allocate are at most
    ``max_items``. A payload that ends early or holds a byte msgpack never uses is left to
    msgpack to refuse.
    """
    end, pos, pending, items = len(payload), 0, 1, 0
    fixed, sized = _FIXED_SIZE, _SIZED
    while pending and pos < end:
        pending -= 1
        b = payload[pos]
        step = fixed[b]
        if step:
            pos += step
            continue
        kind, width, extra = sized[b]
        if width:
            count = int.from_bytes(payload[pos + 1:pos + 1 + width], "big")
        else:
            count = b & 0x0f
        pos += 1 + width
        if kind == "sized":
            pos += extra + count
            continue
        items += count + 1
        if items > max_items:
            raise _TooManyItems(f"more than {max_items} entries in all")
        pending += 2 * count if kind == "map" else count


class _DuplicateKey(ValueError):
    pass


def unpack_map(payload: bytes, what: str = "message", *, max_map_len: int = MAX_MAP_LEN,
               max_items: int = MAX_ITEMS, max_payload: int = MAX_PAYLOAD,
               unique_keys: bool = True) -> dict:
    """The msgpack map of a payload, unpacked within this module's bounds (the map's and the
    total's larger for a worker's status: :func:`decode_status`).

    The per-container limits (MAX_MAP_LEN, MAX_ARRAY_LEN, MAX_STR_LEN, MAX_EXT_LEN) make msgpack
    refuse a container when it reads its header, before building it; the total (``max_items``)
    is counted on the containers' headers before msgpack reads the payload
    (:func:`_declared_entries`), so neither nesting nor containers that never complete can
    multiply the per-container limits. What is built is therefore at most about 2 x
    ``max_items`` objects plus the bytes of the strings and binaries, which the payload holds
    anyway.

    With ``unique_keys`` a map that gives a key twice is refused (``undecodable``): its pairs
    are then kept until the map completes, about 64 bytes each beyond a dict's entry, at most
    ``max_items`` of them (1 MiB for a message's bounds, 16 MiB for a status map's, hence
    :func:`decode_status` reads without the check).

    Raises
    ------
    MessageError
        ``oversized``, ``undecodable`` (including a container over a bound) or ``not-a-map``.
    """
    if len(payload) > max_payload:
        raise MessageError("oversized", f"{what} of {len(payload)} bytes, the limit is "
                           f"{max_payload}")

    def unique(pairs):
        # a key given twice would be read as its last value here and maybe its first by
        # another reader (a dashboard, a proxy): refuse the ambiguity rather than pick one
        if not isinstance(pairs, list):  # msgpack 1.0.0's pure-Python unpacker: a generator
            pairs = list(pairs)
        mapping = dict(pairs)
        if len(mapping) < len(pairs):
            seen = set()
            twice = next(key for key, _ in pairs if key in seen or seen.add(key))
            raise _DuplicateKey(f"a map gives the key {twice!r:.80} twice")
        return mapping

    hook = {"object_pairs_hook": unique} if unique_keys else {}
    try:
        _declared_entries(payload, max_items)
        obj = msgpack.unpackb(payload, raw=False, strict_map_key=False, **hook,
                              max_str_len=MAX_STR_LEN, max_bin_len=max_payload,
                              max_array_len=MAX_ARRAY_LEN, max_map_len=max_map_len,
                              max_ext_len=MAX_EXT_LEN)
    except Exception as exc:  # msgpack raises several unrelated types on garbage
        why = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        raise MessageError("undecodable", f"{what} is not msgpack ({why})") from None
    if not isinstance(obj, dict):
        raise MessageError("not-a-map", f"{what} is a msgpack {type(obj).__name__}, not a map")
    return obj


# A worker's status map (``<prefix>/@worker/<id>/status``, docs/operations.md): a robot's
# entry per robot tracked and per robot refused lately, so larger maps than a message's, still
# bounded (any process on the prefix can answer a status query).
STATUS_MAX_MAP_LEN = 8192
STATUS_MAX_ITEMS = 1 << 18
STATUS_MAX_BYTES = 16 * 1024 * 1024


def encode_status(status: dict) -> bytes:
    """A worker's status map as it goes on the wire (:func:`decode_status` reads it)."""
    return msgpack.packb(status, use_bin_type=True)


def decode_status(payload: bytes) -> dict:
    """A worker's status map (built by :meth:`service.core.WorkerCore.status` and the worker),
    unpacked within the status bounds. A key given twice is read as its last value: refusing it
    (as messages do) would keep every pair of the maps being read, up to the status bounds'
    262,144 (16 MiB, :func:`unpack_map`); a status only informs (``asnn status``, the health
    check).

    Raises
    ------
    MessageError
        As :func:`unpack_map`, or ``invalid-field`` where it names no ``worker``.
    """
    status = unpack_map(payload, "status", max_map_len=STATUS_MAX_MAP_LEN,
                        max_items=STATUS_MAX_ITEMS, max_payload=STATUS_MAX_BYTES,
                        unique_keys=False)
    if not isinstance(status.get("worker"), str):
        raise MessageError("invalid-field", "a status map names its worker")
    return status


class Refusal(_Message):
    """A worker's notice on ``<prefix>/<robot>/refused`` that it refuses the robot's frames
    (an optional extension, docs/contract.md): the latest refusal, at most one notice a second
    per robot, so that the camera can say why nothing answers it."""

    v: int = Field(VERSION, description="message version (1)")
    robot: str = Field(pattern=f"^{keys.ROBOT_PATTERN.pattern}$")
    worker: str = Field(min_length=1, max_length=MAX_NOTE_LEN)
    reason: str = Field(pattern=rf"^[A-Za-z0-9_.:-]{{1,{MAX_REASON_LEN}}}$",
                        description="the label counted, REASONS and the worker's own "
                        "(docs/operations.md)")
    detail: str = Field(max_length=MAX_NOTE_LEN)
    count: int = Field(ge=1, description="frames of the robot this worker has refused")


def decode_refusal(payload: bytes, robot: str | None = None) -> Refusal:
    """Validate a Refusal payload (a small message: at most MAX_REFUSAL_BYTES), of ``robot``
    where given (the robot of the key it came on)."""
    if len(payload) > MAX_REFUSAL_BYTES:
        raise MessageError("oversized", f"refusal of {len(payload)} bytes, more than "
                           f"{MAX_REFUSAL_BYTES}")
    notice = _validate(Refusal, _unpack(payload, "refusal"), "refusal")
    if robot is not None and notice.robot != robot:
        raise MessageError("bad-key", f"a refusal of robot {notice.robot!r} on robot {robot!r}'s "
                           "key")
    return notice


def _unpack(payload: bytes, what: str) -> dict[str, Any]:
    obj = unpack_map(payload, what)
    for key in obj:  # a packer that writes keys as bin was read as "no version" before
        if not isinstance(key, str):
            raise MessageError("invalid-field", f"{what}'s keys must be msgpack strings (str), "
                               f"got the {type(key).__name__} key {key!r:.60}")
    if "v" not in obj:  # CONTRACT.md lists it in every message: a message without it is invalid
        raise MessageError("missing-field", f"{what} without its version 'v'")
    version = obj["v"]
    if version != VERSION or isinstance(version, bool):
        raise MessageError("unsupported-version", f"{what} version {version!r}, expected {VERSION}")
    return obj


def _validate(model: type[BaseModel], obj: dict, what: str):
    try:
        return model.model_validate(obj)
    except ValidationError as exc:
        errors = exc.errors()
        fields = "; ".join(f"{'.'.join(map(str, e['loc'])) or '?'}: {e['msg']}"
                           for e in errors[:3])
        raise MessageError(_reason(errors[0]) if errors else "invalid-field",
                           f"{what}: {fields}") from None


_FIELD_REASONS = {"stamp": "bad-stamp", "width": "bad-size", "height": "bad-size",
                  "format": "bad-format"}


def _reason(error: dict) -> str:
    """The counting label of pydantic's first validation error."""
    loc = error.get("loc") or ("?",)
    if len(loc) > 1:  # inside a nested field (a target of a response)
        return "invalid-field"
    if error.get("type") == "missing":
        return "missing-field"
    return _FIELD_REASONS.get(str(loc[0]), "invalid-field")


def decode_frame(payload: bytes) -> Frame:
    """Validate a Frame payload (the pixels are checked by :meth:`Frame.image`)."""
    return _validate(Frame, _unpack(payload, "frame"), "frame")


def decode_response(payload: bytes) -> Response:
    """Validate a Response payload."""
    return _validate(Response, _unpack(payload, "response"), "response")


TRACK_ID_SPAN = 1 << 16  # target ids a model may number before they could meet a later one's


def track_id_base(seq: int) -> int:
    """The first target id of a robot's model that starts at frame ``seq`` (a new robot, a
    reset, a hand-over to another worker): ``(seq mod 2^37) * 2^16``. Each model numbers its
    tracks from 0, so without a base an id seen before a hand-over would name another object
    after it; with it, two models of one stream number apart unless one of them numbers 2^16
    tracks per frame between their starts, and ids stay below 2^53 (exact as a JavaScript
    number)."""
    return (seq % (1 << 37)) * TRACK_ID_SPAN


def track_label(target_id: int) -> str:
    """A wire target id as people read it: ``"25:3"`` for track 3 of the model that started at
    frame 25 (:func:`track_id_base`), ``"3"`` for a model that started at frame 0."""
    start, track = divmod(target_id, TRACK_ID_SPAN)
    return f"{start}:{track}" if start else str(track)


def response_from(result, *, robot: str, frame: Frame, model: str, preset: str, worker: str,
                  latency_ms: float, dropped: int, model_ms: float | None = None,
                  id_base: int = 0, stream_frames: int | None = None) -> Response:
    """Wrap an ``asnn.Response`` (the model's output) for the wire; ``id_base``
    (:func:`track_id_base`) is added to its targets' ids."""
    fields = result.to_dict()
    targets = [TargetMsg(**_finite(t if t.get("id") is None else {**t, "id": t["id"] + id_base}))
               for t in fields.pop("targets")]
    return Response(robot=robot, seq=frame.seq, stamp=frame.stamp, model=model, preset=preset,
                    targets=targets, worker=worker, latency_ms=max(latency_ms, 0.0),
                    dropped=dropped,
                    model_ms=None if model_ms is None else max(model_ms, 0.0),
                    stream_frames=stream_frames, **_finite(fields))


# a target's fields that may be left out: a value the model could not measure (a degenerate
# fit's infinite time to contact) goes out as absent, where 0 would break ttc > 0
_OPTIONAL = frozenset(name for name, field in TargetMsg.model_fields.items()
                      if not field.is_required())


def _finite(fields: dict) -> dict:
    """Plain Python scalars (numpy ones are rejected by strict models); non-finite -> 0, or
    absent (None) for an optional field."""
    out = {}
    for key, value in fields.items():
        if isinstance(value, (bool, np.bool_)):
            out[key] = bool(value)
        elif isinstance(value, (int, np.integer)):
            out[key] = int(value)
        elif isinstance(value, (float, np.floating)):
            out[key] = float(value) if math.isfinite(value) else (
                None if key in _OPTIONAL else 0.0)
        else:
            out[key] = value
    return out


# ---------------------------------------------------------------- Preview (optional extension)
# ``<prefix>/<robot>/preview``: a low-rate thumbnail of the camera's frames for dashboards
# (docs/contract.md; not part of CONTRACT.md's required interface, the worker ignores it).

__all__ += ["MAX_PREVIEW_BYTES", "MAX_PREVIEW_PIXELS", "PREVIEW_WIDTH", "Preview", "check_preview",
            "decode_preview"]

PreviewFormat = Literal["jpeg", "png"]
PREVIEW_QUALITY = 70
PREVIEW_WIDTH = 160  # thumbnail width in pixels (never scaled up)
MAX_PREVIEW_BYTES = 64 * 1024  # receivers refuse larger thumbnails (asnn camera's are ~5 KiB)
# ... and thumbnails of more pixels, before decoding them: 64 KiB of png can declare a whole
# 4096x4096 RGBA image, which took a viewer 0.36 s of CPU and 110 MB to decode (a legit
# thumbnail: 0.25 ms); asnn camera's are at most 160 x 4096 (PREVIEW_WIDTH, never scaled up)
MAX_PREVIEW_PIXELS = 1 << 20


class Preview(Frame):
    """A thumbnail of the frame ``seq``: a Frame whose data is a small jpeg (or png) image.

    ``frame_width`` x ``frame_height`` is the size of the published frame, the coordinate system
    of the worker's targets (default: the thumbnail's own size).
    """

    format: PreviewFormat
    frame_width: int | None = Field(None, ge=1, le=MAX_SIDE)
    frame_height: int | None = Field(None, ge=1, le=MAX_SIDE)

    @classmethod
    def from_frame_image(cls, image: np.ndarray, *, seq: int, stamp: float,
                         width: int = PREVIEW_WIDTH, format: str = "jpeg") -> Preview:
        """Scale a gray or BGR uint8 frame down to ``width`` pixels (never up) and encode it
        (ValueError where the encoder refuses it)."""
        import cv2

        h, w = image.shape[:2]
        tw = max(1, min(int(width), w))
        th = max(1, round(h * tw / w))
        small = image if tw == w else cv2.resize(image, (tw, th), interpolation=cv2.INTER_AREA)
        data = images.encode(small, format, PREVIEW_QUALITY)
        return cls(seq=seq, stamp=stamp, width=tw, height=th, format=format, data=data,
                   frame_width=w, frame_height=h)


def decode_preview(payload: bytes) -> Preview:
    """Validate a Preview payload (the image is checked by :meth:`Preview.image`)."""
    return _validate(Preview, _unpack(payload, "preview"), "preview")


def check_preview(preview: Preview) -> np.ndarray:
    """What a viewer checks before it shows a thumbnail: at most MAX_PREVIEW_BYTES and
    MAX_PREVIEW_PIXELS, and an image of the announced size (decoded, and returned).

    Raises
    ------
    MessageError
        ``oversized``, or as :meth:`Preview.image`.
    """
    if len(preview.data) > MAX_PREVIEW_BYTES:
        raise MessageError("oversized", f"preview of {len(preview.data)} bytes, more than "
                           f"{MAX_PREVIEW_BYTES}")
    preview.check_size()  # the header first: a file that is no such image says so
    if preview.width * preview.height > MAX_PREVIEW_PIXELS:
        raise MessageError("oversized", f"preview of {preview.width}x{preview.height} pixels, "
                           f"more than {MAX_PREVIEW_PIXELS}")
    return preview.image()
