"""Encoded pictures (jpeg, png) checked before they are decoded: a lying or hostile header is
refused before any pixel memory is allocated.

Shared by the ROS 2 bag reader (``sensor_msgs/msg/CompressedImage``) and the service's frame and
preview messages (``service.messages``).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["ENCODED_FORMATS", "MAX_SIDE", "ImageError", "decode_encoded", "encoded_size",
           "to_uint8"]

MAX_SIDE = 4096  # largest accepted picture width or height, whatever its source
ENCODED_FORMATS = ("jpeg", "png")


class ImageError(ValueError):
    """A picture that cannot be taken. ``reason`` is a short label for counting."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


def encoded_size(data: bytes, format: str) -> tuple[int, int] | None:
    """(width, height) from a png or jpeg file's header without decoding it; None if the data
    does not start like such a file."""
    data = memoryview(data).cast("B") if format == "jpeg" else bytes(data[:32])
    if format == "png":
        if len(data) < 24 or data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
            return None
        return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    if format != "jpeg" or bytes(data[:2]) != b"\xff\xd8":
        return None
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0x01, 0xD8) or 0xD0 <= marker <= 0xD7:  # no length field
            i += 2
            continue
        if marker in (0xD9, 0xDA):  # end of image, start of scan: no frame header before
            return None
        length = int.from_bytes(data[i + 2:i + 4], "big")
        if length < 2:
            return None
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):  # a start of frame
            if i + 9 > len(data) or length < 7:
                return None
            height = int.from_bytes(data[i + 5:i + 7], "big")
            width = int.from_bytes(data[i + 7:i + 9], "big")
            return width, height
        i += 2 + length
    return None


def decode_encoded(data: bytes, format: str, max_side: int = MAX_SIDE) -> np.ndarray:
    """Decode a jpeg or png file into gray (H, W) or BGR (H, W, 3), at OpenCV's bit depth.

    The header's size is checked (sides 1..``max_side``) before anything is decoded; an alpha
    channel is dropped. 16-bit pngs stay uint16 (see :func:`to_uint8`).

    Raises
    ------
    ImageError
        ``bad-image`` for data that is not a decodable ``format`` file, ``bad-size`` for a
        picture larger than ``max_side`` or of another size than its header says.
    """
    if format not in ENCODED_FORMATS:
        raise ImageError("bad-format", f"{format!r} is not one of {', '.join(ENCODED_FORMATS)}")
    size = encoded_size(data, format)
    if size is None:
        raise ImageError("bad-image", f"data is not a {format} file")
    w, h = size
    if not (1 <= w <= max_side and 1 <= h <= max_side):
        raise ImageError("bad-size", f"{format} image of {w}x{h}; sides must be 1..{max_side}")
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise ImageError("bad-image", f"{format} data does not decode "
                         f"({str(exc).strip().splitlines()[-1][:80]})") from None
    if image is None:
        raise ImageError("bad-image", f"data is not a decodable {format} image")
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
