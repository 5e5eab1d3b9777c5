"""Reading video files into frames (at most :data:`asnn.io.images.MAX_SIDE` a side), and
checking one written."""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np

from .files import LOOP_OF_LINKS, link_loops, seekable_target
from .images import MAX_SIDE
from .rates import FPS_RANGE, MAX_FPS

__all__ = ["DEFAULT_FPS", "FPS_RANGE", "MAX_FPS", "RAW_STREAM_SUFFIXES", "WRITABLE_SUFFIXES",
           "VideoError", "VideoClip", "check_written", "cut_short", "open_video", "open_writer",
           "ignored_fps", "quiet_opencv", "read_frames", "stated_fps", "writable_fps",
           "write_video"]

DEFAULT_FPS = 20.0  # the rate a source that states none (or an implausible one) is timed at
# raw streams, which OpenCV decodes but which carry no timing: it reads them at 25 fps
# (.mjpeg/.mjpg from IP and USB cameras, .h264/.h265 from a Raspberry Pi's)
RAW_STREAM_SUFFIXES = (".264", ".265", ".h264", ".h265", ".hevc", ".mjpeg", ".mjpg")
# the containers our video writers (OpenCV's, mp4v or MJPG) write and read back; OpenCV takes
# the container from the name, and refuses others (.txt) or writes what it cannot read (.mpg)
WRITABLE_SUFFIXES = (".avi", ".m4v", ".mkv", ".mov", ".mp4")
# the slowest rate a video is written at (mpeg4's writer fails below about 0.002 frames a
# second: a bag whose stamps are minutes apart; the fastest is MAX_FPS)
MIN_WRITTEN_FPS = 0.01

# FFmpeg prints its own decoder complaints on stderr; our errors say it in one line instead.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


class VideoError(OSError):
    """A file that cannot be opened or decoded as video."""


def _container(path: Path) -> bool:
    """Whether a file begins as an MP4/MOV (``ftyp``), Matroska/WebM (EBML) or AVI (``RIFF``
    ... ``AVI ``) does: OpenCV does not open an empty MP4 or MKV, which is then told apart
    from a file that is no video by these bytes alone."""
    try:
        with open(path, "rb") as f:
            head = f.read(12)
    except OSError:
        return False
    return (head[4:8] == b"ftyp" or head[:4] == b"\x1a\x45\xdf\xa3"
            or (head[:4] == b"RIFF" and head[8:12] == b"AVI "))


class VideoClip:
    """Frames of a video file, decoded lazily, BGR uint8 as OpenCV reads them.

    Attributes
    ----------
    path : Path
    fps : float
        Frames per second stated by the file, or :data:`DEFAULT_FPS` where it states none or
        one above :data:`MAX_FPS` (:func:`stated_fps`).
    fps_stated : bool
        Whether ``fps`` is the file's own.
    fps_ignored : float or None
        The rate the file states where it is not timed at it, being above :data:`MAX_FPS`
        (:func:`ignored_fps`); None otherwise.
    frame_count : int
        Frame count stated by the file (may be approximate; 0 when unknown).
    width, height : int
    decoder_threads : int or None
        Threads the decoder may use (None: OpenCV's choice, as many as there are cores).
    """

    def __init__(self, path: str | Path, decoder_threads: int | None = None):
        self.path = Path(path)
        self.decoder_threads = decoder_threads
        try:
            str(self.path).encode("utf-8")
        except UnicodeEncodeError:  # bytes of another encoding: OpenCV crashes on the name
            raise VideoError(f"{str(self.path)!r}: a file name that is not UTF-8, which OpenCV "
                             "cannot open: rename the file") from None
        if self.path.is_dir():
            raise VideoError(f"{self.path}: is a folder, not a video file")
        if not self.path.is_file():
            raise VideoError(
                f"{self.path}: not a regular file (a pipe or a device)" if self.path.exists()
                else f"{self.path}: a link to {self.path.readlink()}, which " + (
                    LOOP_OF_LINKS if link_loops(self.path)
                    else "is not there")
                if self.path.is_symlink() else f"{self.path}: no such file")
        cap = self._capture()
        opened = cap.isOpened()
        ok, first = cap.read() if opened else (False, None)
        if not ok or first is None:
            cap.release()
            raise VideoError(f"{self.path}: " + (
                "a video without a frame OpenCV can decode (an empty one, or frames in a "
                "codec it lacks)" if opened or _container(self.path) else
                "not a video OpenCV can decode"))
        reported = cap.get(cv2.CAP_PROP_FPS)
        fps = stated_fps(reported)
        # OpenCV's 25 fps for a raw stream, or a y4m without its F field, is its own default:
        # timed at it, but said to be a guess (asnn detect's and asnn camera's notes)
        states_rate = _states_rate(self.path)
        self.fps_stated = fps is not None and states_rate
        self.fps_ignored = ignored_fps(reported) if states_rate else None
        self.fps = DEFAULT_FPS if fps is None else fps
        self.frame_count = max(int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0), 0)
        self.height, self.width = first.shape[:2]
        cap.release()
        _check_size(self.path, self.width, self.height)

    def _capture(self) -> cv2.VideoCapture:
        if self.decoder_threads is not None:
            cap = cv2.VideoCapture(str(self.path), cv2.CAP_ANY,
                                   [cv2.CAP_PROP_N_THREADS, self.decoder_threads])
            if cap.isOpened():
                return cap
            cap.release()  # a backend without the property: its own number of threads
        return cv2.VideoCapture(str(self.path))

    def __iter__(self) -> Iterator[np.ndarray]:
        return read_frames(self._capture(), self.path)


def _states_rate(path: Path) -> bool:
    """Whether the file can state a frame rate of its own: not a raw stream, and a y4m only
    with its header's ``F`` field (``YUV4MPEG2 W.. H.. F30:1 ...``)."""
    suffix = path.suffix.lower()
    if suffix in RAW_STREAM_SUFFIXES:
        return False
    if suffix == ".y4m":
        try:
            with open(path, "rb") as f:
                header = f.readline(4096).split()
        except OSError:
            return False
        return any(field.startswith(b"F") for field in header[1:])
    return True


def stated_fps(value: float) -> float | None:
    """A frame rate as OpenCV reports it (``CAP_PROP_FPS``), or None where it is not one a
    camera runs at: 0, negative or not finite (none stated), or above :data:`MAX_FPS`. Some
    containers report their time base instead (1000 for a variable-rate WebM): timed at that
    rate, every per-second figure of the model (expansion, time to contact) would be 30 to 50
    times off."""
    return float(value) if value and np.isfinite(value) and 0 < value <= MAX_FPS else None


def ignored_fps(value: float) -> float | None:
    """The frame rate OpenCV reports (``CAP_PROP_FPS``) where a rate is stated but
    :func:`stated_fps` does not take it, being above :data:`MAX_FPS`; else None. Kept so that
    the note on the guessed rate can say what the file states (500), not that it states
    none."""
    return float(value) if np.isfinite(value) and value > MAX_FPS else None


def cut_short(stated: int, decoded: int) -> str | None:
    """What to say of a video that decodes to clearly fewer frames than its container states
    (a file cut or damaged partway: decoding stops where it breaks, with no error), or None.
    Some containers overstate by a frame or two, so a shortfall counts from 2 % or 3 frames."""
    if stated <= 0 or stated - decoded <= max(2, 0.02 * stated):
        return None
    return (f"{decoded} frames decoded where the file states {stated}: it may be cut or "
            "damaged partway")


def _check_size(name, width: int, height: int) -> None:
    """Refuse frames larger than :data:`asnn.io.images.MAX_SIDE` a side, as the wire and the
    bags do: an 8192x8192 clip took 6.5 GB in ``asnn detect`` (the models' state at its size)."""
    if max(width, height) > MAX_SIDE:
        raise VideoError(f"{name}: frames of {width}x{height}; at most {MAX_SIDE} px a side "
                         "are taken (scale the video down first)")


def read_frames(capture: cv2.VideoCapture, name: str = "capture") -> Iterator[np.ndarray]:
    """Frames of an open OpenCV capture until it ends; the capture is released afterwards.

    Raises
    ------
    VideoError
        At a frame larger than :data:`asnn.io.images.MAX_SIDE` a side.
    """
    try:
        while True:
            ok, frame = capture.read()
            if not ok:
                return
            _check_size(name, frame.shape[1], frame.shape[0])
            yield frame
    finally:
        capture.release()


def open_video(path: str | Path, decoder_threads: int | None = None) -> VideoClip:
    """Open a video file, checking that its first frame decodes.

    ``decoder_threads`` limits the threads its decoder uses (a process that keeps the cores
    busy with threads of its own gains nothing from more); the frames are the same.

    Raises
    ------
    VideoError
        If the file is missing or not a decodable video.
    """
    return VideoClip(path, decoder_threads)


def check_written(path: str | Path, frames: int) -> tuple[int, int]:
    """Check that a video OpenCV's ``VideoWriter`` has written and released holds its frames;
    their size as written, (width, height): the encoders round an odd one down without a word.

    The writer reports nothing when a write fails (``write`` returns None in Python; FFmpeg
    only logs a warning): on a full disk an MP4 loses its index, written last, and does not
    open at all. Reading the file back is the one reliable signal: it must open, state
    ``frames`` frames and decode its last one.

    Raises
    ------
    VideoError
        If it does not; the message says why, a full disk where the file's folder has no room.
    """
    path = Path(path)
    capture = cv2.VideoCapture(str(path))
    try:
        stated = int(capture.get(cv2.CAP_PROP_FRAME_COUNT) or 0) if capture.isOpened() else -1
        last_decodes = stated == frames and _decodes(capture, frames - 1)
        size = (int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)),
                int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)))
    finally:
        capture.release()
    if last_decodes:
        return size
    if _disk_full(path):
        raise VideoError(f"cannot write {path}: No space left on device (the video is cut "
                         "short)")
    found = "does not open" if stated < 0 else f"holds {stated} of {frames} frames"
    raise VideoError(f"cannot write {path}: the video written {found}")


class _QuietOpenCV:
    """OpenCV's log level is one for the process: the blocks of :func:`quiet_opencv` that
    overlap (threads opening captures at once) share one lowering, made by the first to enter
    and undone by the last to leave. Each restoring the level it had found left OpenCV held to
    its errors for good where two blocks ended out of order."""

    def __init__(self):
        self.lock = threading.Lock()
        self.blocks = 0  # the blocks running
        self.level = None  # the level the first of them found

    def enter(self) -> None:
        with self.lock:
            if self.blocks == 0:
                get, put, error = _log_level_calls()
                self.level = get()
                put(min(self.level, error))
            self.blocks += 1

    def leave(self) -> None:
        with self.lock:
            self.blocks -= 1
            if self.blocks == 0:
                _log_level_calls()[1](self.level)


_QUIET = _QuietOpenCV()


@contextmanager
def quiet_opencv():
    """OpenCV's own log held to its errors while the block runs, its level restored after: its
    warnings (``[ WARN:0@...]`` lines on stderr) are for the caller to say in its own words. A
    level already quieter (``OPENCV_LOG_LEVEL=SILENT``) is kept; blocks that overlap, on
    several threads, restore it once the last ends (:class:`_QuietOpenCV`)."""
    _QUIET.enter()
    try:
        yield
    finally:
        _QUIET.leave()


def _log_level_calls():
    """OpenCV's log level getter, setter and its ERROR level: ``cv2.utils.logging`` from
    OpenCV 4.13, ``cv2.getLogLevel``/``cv2.setLogLevel`` (ERROR is 2) before it (the versions
    pyproject.toml accepts: 4.12 raised an AttributeError on every video written)."""
    log = getattr(cv2.utils, "logging", None)
    if log is not None:
        return log.getLogLevel, log.setLogLevel, log.LOG_LEVEL_ERROR
    return cv2.getLogLevel, cv2.setLogLevel, 2


def _decodes(capture: cv2.VideoCapture, index: int) -> bool:
    """Whether frame ``index`` of an open capture decodes (the first is the ``0``th)."""
    if index > 0:
        capture.set(cv2.CAP_PROP_POS_FRAMES, index)
    ok, frame = capture.read()
    return bool(ok) and frame is not None


def _disk_full(path: Path) -> bool:
    """Whether the file system that holds ``path`` has no room left for an ordinary user."""
    try:
        stats = os.statvfs(path.parent if str(path.parent) else ".")
    except (OSError, AttributeError):  # no statvfs on Windows
        return False
    return stats.f_bavail * stats.f_frsize < 64 * 1024


def writable_fps(fps: float) -> float:
    """A source's frame rate for the video written of it: ``fps`` where the encoders take it
    (from MIN_WRITTEN_FPS to :data:`MAX_FPS`), else :data:`DEFAULT_FPS`."""
    return fps if MIN_WRITTEN_FPS <= fps <= MAX_FPS else DEFAULT_FPS


def open_writer(path: str | Path, fps: float, size: tuple[int, int]) -> cv2.VideoWriter:
    """OpenCV's writer of a BGR video of ``size`` (width, height) frames at ``fps``: MJPG for
    .avi, mp4v for the other :data:`WRITABLE_SUFFIXES`. OSError where OpenCV cannot open it."""
    path = Path(path)
    fourcc = cv2.VideoWriter_fourcc(*("MJPG" if path.suffix.lower() == ".avi" else "mp4v"))
    writer = cv2.VideoWriter(str(path), fourcc, fps, size, isColor=True)
    if not writer.isOpened():
        raise OSError(f"cannot write video {path}")
    return writer


def write_video(frames: np.ndarray | Iterable[np.ndarray], path: str | Path,
                fps: float = 20.0) -> Path:
    """Write gray uint8 frames (T, H, W), or (H, W) frames one by one from an iterable (a long
    clip need not be held at once), to a video file (mp4v for .mp4, MJPG for .avi).

    Raises
    ------
    OSError
        If OpenCV cannot open a writer for the path, or the file written does not hold the
        frames (a full disk: the writer itself fails silently), or holds them at another size
        (an odd width or height, which the encoders round down; the file is removed).
    ValueError
        For an iterable without frames (an empty array writes an empty video), or a path that
        exists and is not a regular file (:func:`~asnn.io.files.seekable_target`).
    """
    path = Path(path)
    seekable_target(path)
    if isinstance(frames, np.ndarray):
        h, w = frames.shape[1:3]
    else:
        frames = iter(frames)
        first = next(frames, None)
        if first is None:
            raise ValueError(f"no frames to write to {path}")
        h, w = first.shape[:2]
        frames = itertools.chain([first], frames)
    writer = open_writer(path, fps, (w, h))
    written = 0
    try:
        # a writer that fails logs a warning for every frame: a failed write is raised once,
        # below
        with quiet_opencv():
            for frame in frames:
                writer.write(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR))
                written += 1
    finally:
        writer.release()
    if written and check_written(path, written) != (w, h):
        path.unlink()  # not the frames asked for, whose labels are in their pixels
        raise OSError(f"cannot write {path} at {w}x{h}: OpenCV's encoder writes even sizes "
                      "only (give an even size, or a .mcap bag)")
    return path
