"""A camera's frames as it sent them, recorded as a ROS 2 bag (``asnn camera --record``).

Each frame goes to one image topic of a new MCAP file in the types :mod:`asnn.io.rosbag` reads
(and rosbag2 writes): a ``gray8`` or ``bgr8`` frame as a ``sensor_msgs/msg/Image`` (``mono8``,
``bgr8``: its very pixels), a ``jpeg`` or ``png`` one as a ``sensor_msgs/msg/CompressedImage``
(the very bytes sent), stamped with the frame's ``stamp`` (header stamp, log and publish time).
So ``asnn detect OUT.mcap`` and ``asnn camera --source OUT.mcap`` replay the frames the camera
sent, with the times it gave them (its gaps included).

The file is written on a thread of its own: the camera hands a frame over
(:meth:`BagRecording.write`, which neither blocks nor raises) and goes on publishing, so a slow
disk never holds the frames up. The recording stops for good, once, and says why to
``on_stop``: at its size bound (``bound``), at the first write that failed (``failed``: a full
disk), or when the frames waiting for the disk pass ``backlog_bytes`` (``behind``: a disk that
does not keep up). The file then holds every frame up to there and is finished (its index and
summary) at once; otherwise when the recording is closed.

Uses the MCAP project's ROS 2 writer (``mcap-ros2-support``, the optional ``ros`` extra).
"""

from __future__ import annotations

import os
import queue
import shutil
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .files import RecordingFile
from .rosbag import (COMPRESSED_IMAGE, IMAGE, Ros2Writer, compressed_image_message,
                     raw_image_message, register_image_type, ros_time_ns)

__all__ = ["BagRecording", "FRAME_TYPES", "MAX_BACKLOG_BYTES", "MIN_FREE_BYTES"]

# the message type of each of the service's frame formats (service.messages.FORMATS)
FRAME_TYPES = {"gray8": IMAGE, "bgr8": IMAGE, "jpeg": COMPRESSED_IMAGE, "png": COMPRESSED_IMAGE}
MAX_BACKLOG_BYTES = 64 * 2**20  # frames waiting for the disk: 11 s of 640x480 gray8 at 20 fps
# a disk with less room than this is full at the start: the file's first chunks (1 MiB each,
# the writer holds the one being filled) would fail within seconds of frames
MIN_FREE_BYTES = 16 * 2**20

_END, _STOP = object(), object()  # the queue's markers: closed; stop where the frames are


class BagRecording:
    """A new MCAP file recording a camera's frames on ``topic`` as they are handed over.

    Parameters
    ----------
    path : str or Path
        The file: it must not exist (a recording never overwrites one).
    topic : str
        The image topic (``/<prefix>/<robot>/frame`` for ``asnn camera``).
    frame_format : {'gray8', 'bgr8', 'jpeg', 'png'}
        The format of every frame handed over (:data:`FRAME_TYPES`).
    frame_id : str
        The messages' ``header.frame_id``.
    max_bytes : float
        The recording stops once the file reaches this size (checked as the writer writes, a
        chunk of frames at a time, so it may pass the bound by a chunk and the summary).
    backlog_bytes : int
        The frames' bytes that may wait for the disk; more stop the recording.
    on_stop : callable(reason, detail), optional
        Called once, on the thread that found it, when the recording stops before it is
        closed: ``reason`` one of ``bound``, ``failed``, ``behind``; ``detail`` one line.

    Attributes
    ----------
    frames : int
        The frames written so far; after a write that failed, those the file holds (the
        frames of the chunks written whole: the writer holds the frames of the chunk it
        fills, which a failed write loses).
    stopped : str or None
        Why the recording stopped before it was closed (``on_stop``'s reason), or None.
    free_bytes : int or None
        Room on the file's disk at the start (None where it cannot be read).

    Raises
    ------
    OSError
        One line: the file exists, cannot be created, or its disk is full (less than
        :data:`MIN_FREE_BYTES` free, or the file's header cannot be written); the file is
        then not left behind (unless it was there before).
    """

    def __init__(self, path: str | Path, topic: str, *, frame_format: str = "gray8",
                 frame_id: str = "camera", max_bytes: float = 1e9,
                 backlog_bytes: int = MAX_BACKLOG_BYTES,
                 on_stop: Callable[[str, str], None] | None = None):
        if frame_format not in FRAME_TYPES:
            raise ValueError(f"unknown frame format {frame_format!r}; choose one of "
                             f"{', '.join(FRAME_TYPES)}")
        self.path, self.topic = Path(path), topic
        self.frame_format, self.frame_id = frame_format, frame_id or "camera"
        self.max_bytes, self.backlog_bytes = max_bytes, backlog_bytes
        self._on_stop = on_stop
        self.frames = 0
        self._in_chunks = 0  # the frames of the chunks written to the file (see _run)
        self.stopped: str | None = None
        self.free_bytes = _free_bytes(self.path)
        self._file = RecordingFile(self.path)
        try:
            if self.free_bytes is not None and self.free_bytes < MIN_FREE_BYTES:
                raise OSError(f"its disk is full ({self.free_bytes / 1e6:.1f} MB free)")
            self._writer = Ros2Writer(self._file)
            self._schema = register_image_type(self._writer, FRAME_TYPES[frame_format])
            self._file.flush()  # a disk that takes nothing says so now, not at the first chunk
        except Exception as exc:  # OSError, or the writer's own on a file that failed
            self._file.close()
            try:
                os.unlink(self.path)  # made here, and holds nothing: a retry finds no file
            except OSError:
                pass
            why = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise OSError(f"cannot record to {self.path}: {why}") from None
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._backlog = 0  # bytes of frames queued and not written yet
        self._accepting = True
        self._finished = False
        self._size = 0
        self._thread = threading.Thread(target=self._run, name="asnn-record", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ the camera's side

    time_ns = staticmethod(ros_time_ns)  # a frame's stamp, seconds, as :meth:`write` takes it

    def write(self, width: int, height: int, data: bytes, stamp_ns: int) -> bool:
        """Hand a frame over: ``data`` is its pixels (``gray8``: ``height`` rows of ``width``
        bytes; ``bgr8``: of ``3 * width``) or its encoded file (``jpeg``, ``png``), as the
        camera sent it; ``stamp_ns`` its stamp, nanoseconds since the epoch. Never blocks.
        Returns False once the recording has stopped (the frame is not recorded)."""
        stop = None
        with self._lock:
            if not self._accepting:
                return False
            if self._backlog and self._backlog + len(data) > self.backlog_bytes:
                self._accepting = False
                stop = (f"the disk does not keep up ({self._backlog / 1e6:.0f} MB of frames "
                        "waiting to be written: the file is finished once they are)")
            else:
                self._backlog += len(data)
                self._queue.put((int(width), int(height), data, int(stamp_ns)))
        if stop is not None:
            self._queue.put(_STOP)  # the frames before are written, then the file finished
            self._stop("behind", stop)
            return False
        return True

    @property
    def size(self) -> int:
        """Bytes written to the file so far (the file's, once finished)."""
        return self._size if self._finished else self._file.tell()

    @property
    def writing(self) -> bool:
        """Whether the writing thread still runs (after :meth:`close`: the file is not
        finished yet)."""
        return self._thread.is_alive()

    def close(self, timeout: float | None = None) -> OSError | None:
        """Write the frames handed over, finish the file (its index and summary) and stop;
        returns the first error the file met, or None. Waits for the writing thread at most
        ``timeout`` seconds (None: until it is done); closing twice does nothing."""
        with self._lock:
            self._accepting = False
        self._queue.put(_END)
        self._thread.join(timeout)
        return self._file.error

    # ------------------------------------------------------------------ the writing thread

    def _stop(self, reason: str, detail: str) -> None:
        with self._lock:
            if self.stopped is not None:
                return
            self.stopped = reason
            self._accepting = False
        if self._on_stop is not None:
            self._on_stop(reason, detail)

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is _END:
                self._finish()
                return
            if item is _STOP:
                self._finish()
                continue
            width, height, data, stamp_ns = item
            with self._lock:
                self._backlog -= len(data)
            if self._finished:
                continue  # after a stop: let it go
            written = self._file.tell()
            try:
                self._write(width, height, data, stamp_ns)
            except Exception as exc:  # a full disk; anything else the writer met
                why = (exc.strerror or str(exc) if isinstance(exc, OSError)
                       else f"{type(exc).__name__}: {exc}")
                whole = self._finish()
                if not whole:  # the frames of the chunk being filled never reached the file
                    # (counted, the stop and the camera's exit said the file held them)
                    self.frames = self._in_chunks
                ended = "finished" if whole else ("cut there, unfinished (`mcap recover` "
                                                  "repairs it)")
                self._stop("failed", f"{why} (the file holds the {self.frames} frames before, "
                                     f"{ended})")
                continue
            self.frames += 1
            if self._file.tell() != written:  # a chunk was written: it ends with this frame
                self._in_chunks = self.frames
            if self.size >= self.max_bytes:
                self._finish()
                self._stop("bound", f"{self.size / 1e6:.0f} MB, its bound")

    def _write(self, width: int, height: int, data: bytes, stamp_ns: int) -> None:
        if self.frame_format in ("gray8", "bgr8"):
            shape = (height, width) if self.frame_format == "gray8" else (height, width, 3)
            message = raw_image_message(np.frombuffer(data, np.uint8).reshape(shape), stamp_ns,
                                        self.frame_id)
        else:
            message = compressed_image_message(data, self.frame_format, stamp_ns,
                                               self.frame_id)
        self._writer.write_message(self.topic, self._schema, message, log_time=stamp_ns,
                                   publish_time=stamp_ns, sequence=self.frames)
        if self._file.error is not None:  # the writer may have let it pass
            raise self._file.error

    def _finish(self) -> bool:
        """Finish the file where it can be (after a failed write it may not): its index and
        summary, then close it. True when the file is whole."""
        if self._finished:
            return self._file.error is None
        try:
            self._writer.finish()
        except Exception:  # kept in the file's error where it was the disk
            pass
        self._size = self._file.tell()
        self._finished = True
        self._file.close()
        return self._file.error is None


def _free_bytes(path: Path) -> int | None:
    """Room on the disk of ``path``'s folder, or None where it cannot be read."""
    try:
        return shutil.disk_usage(path.parent).free
    except OSError:
        return None
