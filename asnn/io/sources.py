"""Every kind of frame source, opened in one place: video files, capture devices, stream URLs,
generated scenes and ROS 2 bags.

``asnn detect``, ``asnn eval`` and ``asnn camera`` all open their input with
:func:`open_source`, so a new kind of source is added here once. A :class:`Source` yields gray or
BGR uint8 frames with their time in seconds since its first frame.

Source specifications:

``FILE``               any video OpenCV reads; time = frame index / the file's frame rate
``DEVICE_INDEX``       an integer: a capture device (live), unless a file of that name is here
``DEVICE``             a capture device's node, e.g. ``/dev/video0`` (any character device)
``URL``                ``scheme://...``: a stream OpenCV reads, e.g. rtsp (live)
``synthetic:SCENE``    one of ``asnn.stimuli.SCENE_NAMES`` (128x128 at 20 fps), or a case of the
                       labelled suite (``asnn scene --list``)
``BAG.mcap[#TOPIC]``   a ROS 2 bag in MCAP (or a rosbag2 directory: one file or a split bag),
                       the image topic after ``#`` or given as ``topic``; time = the messages'
                       header stamps
                       (needs the ``ros`` extra, :mod:`asnn.io.rosbag`)
"""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .files import path_problem
from .rates import MAX_FPS

__all__ = ["CLOCK_RESET", "CLOCK_RESET_FRAMES", "STAMP_UNSET", "SYNTHETIC", "BackwardStamps",
           "Source", "SourceError", "is_bag", "open_source", "split_topic"]

SYNTHETIC = "synthetic:"
BAG_SUFFIX = ".mcap"
# The reason a bag reader gives ``on_error`` for a camera's clock reset (:mod:`asnn.io.rosbag`):
# a notice, not a rejection, as the frame it names is kept, on the new timeline.
CLOCK_RESET = "clock-reset"
# The reason it gives for a frame whose header stamp is unset (zero) among header stamps and
# whose log time cannot stand for one (not within MAX_FRAME_GAP_S after the latest frame's time,
# or after a clock reset): a notice too, the frame is kept, held at the latest frame's time.
STAMP_UNSET = "stamp-unset"
# Frames in a row whose header stamps all go back from the latest taken, yet advance among
# themselves, that make a new timeline for the bag reader (asnn.io.rosbag): a driver restart
# resetting the camera's clock, or one stamp far ahead that every later frame is late against.
# Real bags carry the odd frame out of order, one or two, and then stamps past the latest again;
# a reset clock goes on from its new time to the end. Three tell them apart while holding
# (detect, eval) or skipping (the camera) only the two frames before it.
CLOCK_RESET_FRAMES = 3

ErrorHandler = Callable[[str, str], None]


class SourceError(OSError):
    """A source that cannot be opened or read. ``reason`` is a short label for counting."""

    def __init__(self, message: str, reason: str = "unreadable"):
        super().__init__(message)
        self.reason = reason


class BackwardStamps:
    """``on_error`` for a bag opened with ``hold_backwards``: counts its frames whose header
    stamp goes back (``count``; the reader yields each at the latest frame's time, so every
    message keeps its frame and its place), its clock resets (``resets``, the first one's
    message ``first_reset``: the frame is kept, on the new timeline) and its frames whose header
    stamp is unset and held at the latest frame's time (``unset``: :data:`STAMP_UNSET`, the
    frame is kept), and raises every other error, as without a handler. :meth:`held` is called
    for each frame going back, :meth:`rebased` for each reset, :meth:`held_unset` for each
    unset stamp held: a subclass may report them, or raise to stop."""

    def __init__(self) -> None:
        self.count = 0
        self.resets = 0
        self.first_reset: str | None = None
        self.unset = 0

    def __call__(self, reason: str, message: str) -> None:
        if reason == CLOCK_RESET:
            self.resets += 1
            if self.first_reset is None:
                self.first_reset = message
            self.rebased(message)
            return
        if reason == STAMP_UNSET:
            self.unset += 1
            self.held_unset(message)
            return
        if reason != "stamp-backwards":
            raise SourceError(message, reason)
        self.count += 1
        self.held(message)

    @property
    def tally(self) -> tuple[int, int, str | None, int]:
        """``(count, resets, first_reset, unset)``: what a clip's warnings say of its stamps
        (:func:`asnn.evaluation.clips.clip_warnings`), as plain values a worker process can
        send back."""
        return self.count, self.resets, self.first_reset, self.unset

    def held(self, message: str) -> None:
        """A frame whose header stamp goes back (``message`` names it), the ``count``-th."""

    def rebased(self, message: str) -> None:
        """A clock reset (``message`` names the frame and the jump), the ``resets``-th: the
        reader yields that frame next, on the new timeline."""

    def held_unset(self, message: str) -> None:
        """A frame whose header stamp is unset, held at the latest frame's time (``message``
        names it), the ``unset``-th: the reader yields that frame next."""


@dataclass
class Source:
    """Frames (gray or BGR uint8), their times, and the source's nominal rate.

    ``frames()`` and ``timed_frames()`` each make one pass over the source; ``live`` sources
    (devices, URLs) cannot be replayed and are paced by their own capture.

    Attributes
    ----------
    name : str
        The specification it was opened from.
    fps : float
        Nominal frame rate (for a bag: the median rate of its first frames).
    live : bool
    _open : callable
        Starts a pass: an iterator of images, or of ``(t, image)`` pairs when ``timed``.
    timed : bool
        Whether the source knows its frames' times (bags); otherwise ``t = index / fps``.
    frame_count : int
        Frames the source says it holds (0: unknown).
    start_ns : int or None
        The first frame's time, nanoseconds since the epoch, where the source records one.
    frame_id : str
        The camera's coordinate frame, where the source records one (ROS ``frame_id``).
    fps_stated : bool
        Whether ``fps`` is the source's own; otherwise it states none, or one no camera runs
        at, and ``fps`` is :data:`asnn.io.video.DEFAULT_FPS` (:func:`asnn.io.video.stated_fps`).
    fps_ignored : float or None
        The rate the source states where it is not timed at it, being above
        :data:`asnn.io.rates.MAX_FPS` (:func:`asnn.io.video.ignored_fps`); None otherwise.
    """

    name: str
    fps: float
    live: bool
    _open: Callable[[], Iterable]
    timed: bool = False
    frame_count: int = 0
    start_ns: int | None = None
    frame_id: str = ""
    fps_stated: bool = True
    fps_ignored: float | None = None

    def rate_problem(self) -> str:
        """Why the source is not timed at a rate of its own (``fps_stated`` false), worded to
        follow its name in a note: the rate it states and the rates taken, where it states
        one above them (a container's time base: 500 or 1000), else that it states none."""
        if self.fps_ignored is None:
            return "states no frame rate a camera runs at"
        return (f"states {self.fps_ignored:g} frames a second, more than a camera runs at (a "
                f"stated rate is taken up to {MAX_FPS:g})")

    def timed_frames(self) -> Iterator[tuple[float, np.ndarray]]:
        """``(t, image)``: seconds since the first frame, and the frame."""
        items = self._open()
        if self.timed:
            yield from items
        else:
            for index, image in enumerate(items):
                yield index / self.fps, image

    def frames(self) -> Iterator[np.ndarray]:
        """The frames alone."""
        for _, image in self.timed_frames():
            yield image


def split_topic(spec: str) -> tuple[str, str | None]:
    """``'run.mcap#/camera/image_raw'`` -> ``('run.mcap', '/camera/image_raw')``; a spec without
    a ``#TOPIC`` suffix -> ``(spec, None)``."""
    head, sep, topic = spec.rpartition("#")
    if sep and is_bag(head):
        return head, topic or None
    return spec, None


def is_bag(path: str) -> bool:
    """Whether a path names a ROS 2 bag: an ``.mcap`` file, or a rosbag2 directory (one with a
    ``metadata.yaml``)."""
    if path.lower().endswith(BAG_SUFFIX):
        return True
    # os.path's, which say False where Path's raise (a name too long: split_topic asks this of
    # a spec's head before open_source can say so in one line)
    return os.path.isdir(path) and os.path.isfile(os.path.join(path, "metadata.yaml"))


def open_source(spec: str, *, topic: str | None = None,
                on_error: ErrorHandler | None = None, hold_backwards: bool = False,
                decoder_threads: int | None = None) -> Source:
    """Open a source (see the module's list), checking that it yields a first frame.

    Parameters
    ----------
    spec : str
        ``FILE``, ``DEVICE_INDEX``, ``URL``, ``synthetic:SCENE`` or ``BAG.mcap[#TOPIC]``.
    topic : str, optional
        The image topic of a bag (instead of a ``#TOPIC`` suffix).
    on_error : callable(reason, message), optional
        For bags: called for a message that cannot be used (skipped) or a cut or corrupt file
        (the frames end there), so that a long-running reader counts and goes on; it may raise
        to stop there instead. Without it, reading raises :class:`SourceError` there.
    hold_backwards : bool
        For bags, with ``on_error``: a frame whose header stamp goes back is reported
        (``stamp-backwards``) and then taken at the latest frame's time instead of skipped
        (``asnn detect``: one result per message). Either way a clock reset (frames in a row
        going back and advancing, :meth:`asnn.io.rosbag.BagClip.frames`) is reported as
        :data:`CLOCK_RESET` and its frames go on from the latest frame's time, and a frame whose
        header stamp is unset (zero) among header stamps, held at the latest frame's time
        (:meth:`asnn.io.rosbag.BagClip.frames`), is reported as :data:`STAMP_UNSET` and kept.
    decoder_threads : int, optional
        For video files: the threads the decoder may use (default: OpenCV's choice).

    Raises
    ------
    SourceError
        If the source does not exist or yields no frame, and for a bag also if the topic is
        missing, empty, not an image topic, or not given while the bag has several. ``str()``
        is one line naming the source.
    """
    spec = str(spec)
    path, suffix_topic = split_topic(spec)
    problem = None if "://" in spec else path_problem(path)  # a URL may have long parts
    if problem:  # Path's checks below raise for it, and a traceback said it
        raise SourceError(f"{path}: {problem}", "unreadable")
    if topic is not None and suffix_topic is not None and topic != suffix_topic:
        raise SourceError(f"{spec}: names the topic {suffix_topic}, and the topic given is "
                          f"{topic}: give one", "two-topics")
    if is_bag(path):
        return _open_bag(path, topic or suffix_topic, on_error, hold_backwards)
    if Path(path).is_dir() and any(Path(path).glob("*.mcap")):
        raise SourceError(f"{path}: a folder of .mcap files without the metadata.yaml of a "
                          "rosbag2 directory: give one .mcap file, or rebuild the metadata "
                          "(ros2 bag reindex)", "not-a-bag")
    _refuse_other_bags(path)
    if topic is not None:
        raise SourceError(f"{spec}: a topic applies to ROS 2 bags (.mcap) only", "no-topic")
    if spec.startswith(SYNTHETIC):
        return _open_scene(spec)
    if (spec.isdigit() and not Path(spec).exists()) or "://" in spec:  # a file named 0 is one
        return _open_capture(spec)
    if _is_device(spec):  # /dev/video0: what people type for their camera
        return _open_capture(spec)
    return _open_file(spec, decoder_threads)


_OTHER_BAGS = {".db3": "a rosbag2 bag stored in SQLite; only MCAP bags are read "
                       "(ros2 bag convert makes one)",
               ".bag": "a ROS 1 bag; only ROS 2 bags in MCAP are read (convert it to one)"}


def _refuse_other_bags(path: str) -> None:
    """A bag in a format not read, by its suffix (or a folder of such files), said as such:
    OpenCV's "not a video" would send the user looking in the wrong place."""
    folder = Path(path)
    for suffix, what in _OTHER_BAGS.items():
        if path.lower().endswith(suffix) or (folder.is_dir() and any(folder.glob(f"*{suffix}"))):
            raise SourceError(f"{path}: {what}", "not-a-bag")


def _is_device(path: str) -> bool:
    try:
        return stat.S_ISCHR(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


def _open_scene(spec: str) -> Source:
    from ..stimuli import SCENE_NAMES, make_scene
    from ..stimuli.suite import CASES, make_case

    name = spec[len(SYNTHETIC):]
    if name in SCENE_NAMES:
        scene = make_scene(name)
    elif name in CASES:
        scene = make_case(name)
    else:
        raise SourceError(f"unknown scene {name!r}; choose one of {', '.join(SCENE_NAMES)} "
                          "or a case of the labelled suite (asnn scene --list)", "missing")
    return Source(spec, scene.fps, False, lambda: iter(scene.frames),
                  frame_count=len(scene.frames))


def _open_capture(spec: str) -> Source:
    import cv2

    from .video import DEFAULT_FPS, ignored_fps, quiet_opencv, read_frames, stated_fps

    # a V4L2 node by its index, as OpenCV's backends all take it
    device = re.fullmatch(r"/dev/video(\d+)", os.path.realpath(spec))
    with quiet_opencv():  # each backend it tries warns of a device that is not there (V4L2,
        # FFmpeg): two lines on stderr before the one error below says it
        cap = cv2.VideoCapture(int(spec) if spec.isdigit() else
                               int(device.group(1)) if device else spec)
    if not cap.isOpened():
        what = "capture device" if _is_device(spec) else "capture source"
        raise SourceError(f"cannot open {what} {spec!r}", "missing")
    reported = cap.get(cv2.CAP_PROP_FPS)
    fps = stated_fps(reported)
    return Source(spec, DEFAULT_FPS if fps is None else fps, True, lambda: read_frames(cap, spec),
                  fps_stated=fps is not None, fps_ignored=ignored_fps(reported))


def _open_file(spec: str, decoder_threads: int | None) -> Source:
    from .video import VideoError, open_video

    try:
        clip = open_video(spec, decoder_threads)
    except VideoError as exc:
        raise SourceError(str(exc), "missing" if "no such file" in str(exc) else
                          "undecodable") from None
    return Source(spec, clip.fps, False, lambda: iter(clip), frame_count=clip.frame_count,
                  fps_stated=clip.fps_stated, fps_ignored=clip.fps_ignored)


def _open_bag(path: str, topic: str | None, on_error: ErrorHandler | None,
              hold_backwards: bool = False) -> Source:
    try:
        from . import rosbag
    except ImportError as exc:  # the message names the extra to install
        raise SourceError(f"{path}: {exc}", "missing-extra") from None
    clip = rosbag.open_bag(path, topic)
    return Source(f"{clip.path}#{clip.topic}", clip.fps, False,
                  lambda: clip.frames(on_error, hold_backwards=hold_backwards), timed=True,
                  frame_count=clip.frame_count,
                  start_ns=clip.start_ns, frame_id=clip.frame_id)
