"""Encoded pictures (jpeg, png) checked before they are decoded: a lying or hostile header is
refused before any pixel memory is allocated.

Shared by the ROS 2 bag reader (``sensor_msgs/msg/CompressedImage``) and the service's frame and
preview messages (``service.messages``), so both get the same protection
(docs/operations.md, "Hostile input"): the header is read first; its sides must be
1..``max_side`` (and the size the caller expects, if any); the file must be an image of a kind
cameras make (baseline, extended or progressive Huffman jpeg of 8-bit samples; png of at most
``max_depth`` bits per sample); and it must be long enough to hold that many pixels at the best
compression its coding allows (:func:`min_encoded_bytes`). A truncated file whose header
declares 4096x4096 is thus refused before the decoder pads it into a 48 MiB picture (and a
worker builds a model state of 0.9 GB for it). The parts read one by one are bounded too: a
jpeg's markers before its first scan (:data:`MAX_JPEG_MARKERS`) and its scans
(:data:`MAX_JPEG_SCANS`); a png's chunks (:data:`MAX_PNG_ANCILLARY`, two a row in all), each
with its CRC checked so that libpng has nothing to warn about on stderr.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

__all__ = ["ENCODED_FORMATS", "JPEG_QUALITY", "MAX_JPEG_MARKERS", "MAX_JPEG_SCANS",
           "MAX_PNG_ANCILLARY", "MAX_SIDE", "ImageError",
           "check_encoded", "decode_encoded", "encode", "encoded_size", "min_encoded_bytes",
           "to_uint8"]

MAX_SIDE = 4096  # largest accepted picture width or height, whatever its source
ENCODED_FORMATS = ("jpeg", "png")
JPEG_QUALITY = 90  # what the project encodes jpeg at: the camera's frames, the MCAP's images
# Each scan of a progressive jpeg makes the decoder visit every block of the image, however few
# bytes the scan takes: 1,000 copies of a 33-byte scan in a 4096x4096 file of 99 KB took 10.8 s
# to decode (the file without them: 0.08 s), and a frame may be 48 MiB. Encoders write 1 scan
# (baseline) to about 10 (progressive); markers inside other segments (an EXIF thumbnail's
# scan) count too, which errs on the side of refusing.
MAX_JPEG_SCANS = 64
# Markers and fill bytes before a jpeg's first scan, each read in turn: 4 MB of fill bytes (or a
# million empty APP0 segments) held the reader 0.7 s, on the thread that receives a worker's
# frames. Encoders write about 10 (an ICC profile split into APP2 segments: some 50 more).
MAX_JPEG_MARKERS = 1024
# png chunks: libpng writes a warning line to stderr for each ancillary chunk whose CRC is
# wrong (1,000 such chunks, 2,000 lines per frame, past any rate limit of ours), and reads
# every chunk, so their number is bounded: ancillary ones (text, colour profile, time...;
# encoders write a handful), and in all (encoders write a chunk or two per row at most).
MAX_PNG_ANCILLARY = 64


class ImageError(ValueError):
    """A picture that cannot be taken. ``reason`` is a short label for counting:
    ``bad-format``, ``bad-image`` (not a whole picture of a supported kind) or ``bad-size``
    (sides out of range, or not the size expected)."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


@dataclass(frozen=True)
class _Header:
    """What an encoded picture's header says, read without decoding it."""

    width: int
    height: int
    kind: str       # "png": its colour type, e.g. "png2"; "jpeg": the start of frame, e.g. "sof0"
    depth: int      # bits per sample
    channels: int   # samples per pixel (png: before palette expansion)
    body: int       # offset of the compressed pixels (jpeg: after the first start of scan;
                    # png: after the header; -1 when the header ends before them)


_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}  # colour type -> samples per pixel
# baseline, extended and progressive Huffman coding: what cameras and encoders produce.
# Lossless, hierarchical and arithmetic-coded jpeg are refused (OpenCV need not decode them,
# and arithmetic coding can make a large image from a few bytes).
_JPEG_PROCESSES = {0xC0: "sof0", 0xC1: "sof1", 0xC2: "sof2"}


def _read_header(data: bytes, format: str) -> _Header | None:
    if format == "png":
        head = bytes(data[:29])
        if len(head) < 29 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
            return None
        return _Header(int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big"),
                       f"png{head[25]}", head[24], _PNG_CHANNELS.get(head[25], 0), 33)
    data = memoryview(data).cast("B")
    if format != "jpeg" or bytes(data[:2]) != b"\xff\xd8":
        return None
    i, frame = 2, None
    for _ in range(MAX_JPEG_MARKERS):
        if i + 4 > len(data):
            break
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0x01, 0xD8) or 0xD0 <= marker <= 0xD7:  # no length field
            i += 2
            continue
        if marker == 0xD9:  # end of image
            break
        length = int.from_bytes(data[i + 2:i + 4], "big")
        if length < 2:
            return None
        if marker == 0xDA:  # start of scan: the compressed pixels follow its header
            if frame is None:
                return None
            return _Header(*frame, body=min(i + 2 + length, len(data)))
        if frame is None and 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            if i + 10 > len(data) or length < 8:
                return None
            frame = (int.from_bytes(data[i + 7:i + 9], "big"),  # width
                     int.from_bytes(data[i + 5:i + 7], "big"),  # height
                     _JPEG_PROCESSES.get(marker, f"0x{marker:02x}"), data[i + 4], data[i + 9])
        i += 2 + length
    else:
        raise ImageError("bad-image", f"jpeg of more than {MAX_JPEG_MARKERS} markers and fill "
                         "bytes before its first scan")
    return None if frame is None else _Header(*frame, body=-1)


def encoded_size(data: bytes, format: str) -> tuple[int, int] | None:
    """(width, height) from a png or jpeg file's header without decoding it; None if the data
    does not start like such a file (or is a jpeg of more than :data:`MAX_JPEG_MARKERS`
    markers before its pixels)."""
    try:
        header = _read_header(data, format)
    except ImageError:
        return None
    return None if header is None else (header.width, header.height)


def min_encoded_bytes(format: str, width: int, height: int, channels: int = 1,
                      depth: int = 8) -> int:
    """The fewest bytes of compressed pixels that can hold a whole ``width`` x ``height`` image.

    jpeg (Huffman coded): every 8x8 block of the full-resolution component costs at least one
    bit (its DC code; a progressive file may leave every AC coefficient out). png: deflate
    cannot compress better than 1032:1, and each row holds a filter byte and
    ``width x channels x depth`` bits.

    Parameters
    ----------
    format : {'jpeg', 'png'}
    width, height : int
    channels, depth : int
        png only: samples per pixel and bits per sample.

    Returns
    -------
    int
    """
    if format == "jpeg":
        blocks = -(-width // 8) * -(-height // 8)
        return blocks // 8
    raw = height * (1 + -(-width * channels * depth // 8))
    return raw // 1032


def check_encoded(data: bytes, format: str, size: tuple[int, int] | None = None, *,
                  max_side: int = MAX_SIDE, max_depth: int = 8) -> tuple[int, int]:
    """Check an encoded picture from its header alone, before anything is decoded.

    Parameters
    ----------
    data : bytes
        The file.
    format : {'jpeg', 'png'}
    size : (int, int), optional
        The (width, height) the picture must have (a message's announced size).
    max_side : int
        Largest accepted width or height.
    max_depth : {8, 16}
        Largest accepted png sample depth (jpeg: 8-bit samples only).

    Returns
    -------
    (int, int)
        The picture's (width, height).

    Raises
    ------
    ImageError
        ``bad-format`` for a format other than jpeg or png; ``bad-image`` when the data is not
        a file of ``format``, not an image of a supported kind or depth, or too short to hold
        a whole image of its size (a truncated file would be padded by the decoder);
        ``bad-size`` for sides outside 1..``max_side`` or other than ``size``.
    """
    header = _checked_header(data, format, size, max_side, max_depth)
    return header.width, header.height


def _checked_header(data, format, size, max_side, max_depth):
    """The header :func:`check_encoded` checks, once checked."""
    if format not in ENCODED_FORMATS:
        raise ImageError("bad-format", f"{format!r} is not one of {', '.join(ENCODED_FORMATS)}")
    header = _read_header(data, format)
    if header is None:
        raise ImageError("bad-image", f"data is not a {format} file")
    w, h = header.width, header.height
    if size is not None and (w, h) != tuple(size):
        raise ImageError("bad-size", f"{format} image is {w}x{h}, the message says "
                         f"{size[0]}x{size[1]}")
    if not (1 <= w <= max_side and 1 <= h <= max_side):
        raise ImageError("bad-size", f"{format} image of {w}x{h}; sides must be 1..{max_side}")
    if format == "jpeg":
        if header.kind not in _JPEG_PROCESSES.values():
            raise ImageError("bad-image", f"jpeg coding {header.kind} is not supported "
                             "(baseline or progressive Huffman only)")
        if header.depth != 8 or header.channels not in (1, 3):
            raise ImageError("bad-image", f"jpeg of {header.channels} components of "
                             f"{header.depth} bits, not 8-bit gray or colour")
        if header.body < 0:
            raise ImageError("bad-image", "jpeg without a start of scan: no pixels")
        whole = data if isinstance(data, bytes) else bytes(data)
        scans = whole.count(b"\xff\xda")
        if scans > MAX_JPEG_SCANS:
            raise ImageError("bad-image", f"jpeg of {scans} scans; at most {MAX_JPEG_SCANS} are "
                             "decoded (cameras' progressive files have about 10)")
        # a file cut short: refused here rather than by the decoder, after its line on stderr
        if not whole.rstrip(b"\x00\xff").endswith(b"\xff\xd9"):
            raise ImageError("bad-image", "jpeg without its end-of-image marker: truncated")
    elif header.depth not in (1, 2, 4, 8, 16) or header.depth > max_depth or not header.channels:
        raise ImageError("bad-image", f"png of {header.depth}-bit samples (colour type "
                         f"{header.kind[3:]}); at most {max_depth}-bit are read")
    need = min_encoded_bytes(format, w, h, header.channels, header.depth)
    if len(data) - header.body < need:
        raise ImageError("bad-image", f"{format} of {len(data)} bytes cannot hold a whole "
                         f"{w}x{h} image (at least {need} bytes of compressed pixels): "
                         "truncated")
    return header


_PNG_CRITICAL = (b"IHDR", b"PLTE", b"IDAT", b"IEND")


def _check_png_chunks(data: bytes, limit: int, height: int) -> None:
    """Refuse a png (:class:`ImageError`, ``bad-image``) whose chunks the decoder should not be
    given: a chunk whose CRC does not match its bytes (libpng warns on stderr for each
    ancillary one), more than :data:`MAX_PNG_ANCILLARY` ancillary chunks or more than
    ``1024 + 2 x height`` chunks in all, no IEND chunk (a truncated file), or compressed
    pixels (its IDAT chunks) that are not deflate or inflate to more than ``limit`` bytes,
    found by inflating them a MiB at a time, none of it kept. The decoder inflates whatever
    follows the rows too: 1 MB of deflate that inflates to 1 GB after a 1024x1024 image took
    it 0.97 s (a frame of 48 MiB: 45 s of a processing thread)."""
    inflater, total, i, chunks, ancillary = zlib.decompressobj(), 0, 8, 0, 0
    view = memoryview(data).cast("B")
    while i + 12 <= len(view):
        length, kind = int.from_bytes(view[i:i + 4], "big"), bytes(view[i + 4:i + 8])
        if i + 12 + length > len(view):
            break
        chunks += 1
        if kind not in _PNG_CRITICAL:
            ancillary += 1
        if ancillary > MAX_PNG_ANCILLARY or chunks > 1024 + 2 * height:
            raise ImageError("bad-image", f"png of more than {MAX_PNG_ANCILLARY} ancillary "
                             f"chunks or {1024 + 2 * height} chunks in all")
        if zlib.crc32(view[i + 4:i + 8 + length]) != int.from_bytes(
                view[i + 8 + length:i + 12 + length], "big"):
            raise ImageError("bad-image", f"png chunk {kind!r:.20} at byte {i} fails its CRC")
        if kind == b"IEND":
            return
        if kind == b"IDAT":
            chunk = view[i + 8:i + 8 + length]
            try:
                while len(chunk) and not inflater.eof:
                    total += len(inflater.decompress(chunk, 1 << 20))
                    if total > limit:
                        raise ImageError("bad-image", "png data inflates to more than its "
                                         "image's rows")
                    chunk = inflater.unconsumed_tail
            except zlib.error as exc:  # libpng would say so on stderr
                raise ImageError("bad-image", f"png data does not inflate ({exc})") from None
        i += 12 + length
    # libpng (and OpenCV) would report the cut on stderr
    raise ImageError("bad-image", "png ends before its IEND chunk: truncated")


def decode_encoded(data: bytes, format: str, size: tuple[int, int] | None = None, *,
                   max_side: int = MAX_SIDE, max_depth: int = 8) -> np.ndarray:
    """Decode a jpeg or png file into gray (H, W) or BGR (H, W, 3), once
    :func:`check_encoded` has accepted its header.

    An alpha channel is dropped. With ``max_depth=16``, 16-bit pngs stay uint16 (see
    :func:`to_uint8`); otherwise the result is uint8.

    Parameters
    ----------
    data, format, size, max_side, max_depth
        As in :func:`check_encoded`.

    Returns
    -------
    ndarray

    Raises
    ------
    ImageError
        As :func:`check_encoded`; ``bad-image`` also for data that does not decode, and
        ``bad-size`` for a picture of another size than its header says.
    """
    import cv2  # here, not with the module: the status and alerts read no picture

    header = _checked_header(data, format, size, max_side, max_depth)
    w, h = header.width, header.height
    if format == "png":
        # the rows, their filter bytes, and room for interlacing's shorter rows
        rows = h * (1 + -(-w * header.channels * header.depth // 8))
        _check_png_chunks(data, rows + 4 * h + 1024, h)
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise ImageError("bad-image", f"{format} data does not decode "
                         f"({str(exc).strip().splitlines()[-1][:80]})") from None
    if image is None:
        raise ImageError("bad-image", f"data is not a decodable {format} image")
    if image.dtype.itemsize * 8 > max_depth:
        raise ImageError("bad-image", f"{format} image is {image.dtype}, more than "
                         f"{max_depth}-bit")
    if image.ndim == 3:
        channels = image.shape[2]
        if channels == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
        elif channels != 3:  # gray + alpha, or anything else: keep the first channel
            image = np.ascontiguousarray(image[:, :, 0])
    if image.ndim not in (2, 3) or image.shape[:2] != (h, w):
        raise ImageError("bad-size", f"{format} image decodes to {image.shape[1]}x"
                         f"{image.shape[0]}, its header says {w}x{h}")
    return image


def encode(image: np.ndarray, format: str, quality: int = JPEG_QUALITY) -> bytes:
    """A gray or BGR uint8 image as a jpeg (at ``quality``) or png file's bytes.

    Raises
    ------
    ValueError
        For another format, or an image the encoder refuses.
    """
    if format not in ENCODED_FORMATS:
        raise ValueError(f"unknown image format {format!r}; choose one of "
                         f"{', '.join(ENCODED_FORMATS)}")
    import cv2

    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if format == "jpeg" else []
    ok, data = cv2.imencode(".jpg" if format == "jpeg" else ".png", image, params)
    if not ok:
        raise ValueError(f"cannot encode a {image.shape} image as {format}")
    return data.tobytes()


def to_uint8(image: np.ndarray) -> np.ndarray:
    """8-bit pixels: uint8 as is, uint16 by its high byte (a fixed scale, so that brightness
    does not change from frame to frame as it would with per-frame normalisation).

    Raises
    ------
    ImageError
        ``bad-image`` for any other pixel type.
    """
    if image.dtype == np.uint8:
        return image
    if image.dtype == np.uint16:
        return (image >> 8).astype(np.uint8)
    raise ImageError("bad-image", f"{image.dtype} pixels; expected 8 or 16 bits")
