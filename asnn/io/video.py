"""Reading video files into frames (the only file I/O of the asnn package)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

__all__ = ["VideoError", "VideoClip", "open_video", "read_frames"]

# FFmpeg prints its own decoder complaints on stderr; our errors say it in one line instead.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


class VideoError(OSError):
    """A file that cannot be opened or decoded as video."""


class VideoClip:
    """Frames of a video file, decoded lazily, BGR uint8 as OpenCV reads them.

    Attributes
    ----------
    path : Path
    fps : float
        Frames per second stated by the file (20 when it states none).
    frame_count : int
        Frame count stated by the file (may be approximate; 0 when unknown).
    width, height : int
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if not self.path.is_file():
            raise VideoError(f"{self.path}: no such file")
        cap = cv2.VideoCapture(str(self.path))
        ok, first = cap.read() if cap.isOpened() else (False, None)
        if not ok or first is None:
            cap.release()
            raise VideoError(f"{self.path}: not a video OpenCV can decode")
        fps = cap.get(cv2.CAP_PROP_FPS)
        self.fps = float(fps) if fps and np.isfinite(fps) and fps > 0 else 20.0
        self.frame_count = max(int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0), 0)
        self.height, self.width = first.shape[:2]
        cap.release()

    def __iter__(self) -> Iterator[np.ndarray]:
        return read_frames(cv2.VideoCapture(str(self.path)))


def read_frames(capture: cv2.VideoCapture) -> Iterator[np.ndarray]:
    """Frames of an open OpenCV capture until it ends; the capture is released afterwards."""
    try:
        while True:
            ok, frame = capture.read()
            if not ok:
                return
            yield frame
    finally:
        capture.release()


def open_video(path: str | Path) -> VideoClip:
    """Open a video file, checking that its first frame decodes.

    Raises
    ------
    VideoError
        If the file is missing or not a decodable video.
    """
    return VideoClip(path)
