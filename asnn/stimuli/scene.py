"""A generated clip with its ground truth, and writing clips to files."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ..io.video import check_written, quiet_writer

__all__ = ["Scene", "write_video", "write_frames"]


@dataclass
class Scene:
    """A generated clip and its ground truth.

    Attributes
    ----------
    name : str
    frames : ndarray of uint8 (T, H, W)
    fps : float
    collision : bool
        Whether something approaches (a looming phase exists).
    onset_frame, contact_frame : int or None
        First and last frame of the (first) looming phase: the frame the approach starts, and the
        frame of contact (or, for an approach that stops or turns back short of contact, the frame
        the approach ends).
    center : (x, y) or None
        Centre of the looming object, pixels (at contact where the centre moves).
    params : dict
        The arguments the scene was made with.
    track : ndarray (T, 2) or None
        Image centre (x, y) of the target in every frame, NaN where there is none; may lie
        outside the frame (an object passing by).
    target_size : ndarray (T,) or None
        The target's image size in pixels (a disk's diameter, a box's height), NaN where none.
    ttc : ndarray (T,) or None
        True time to contact in seconds, distance / closing speed, NaN where the target does not
        approach.
    category : tuple of str
        Tags that say what the clip tests (``loom``, ``nearmiss``, ``dark``, ``camera``, ...).
    twin : str or None
        For a near miss, the name of the collision-course clip with the same object, distance and
        speed.
    """

    name: str
    frames: np.ndarray
    fps: float
    collision: bool
    onset_frame: int | None = None
    contact_frame: int | None = None
    center: tuple[float, float] | None = None
    params: dict = field(default_factory=dict)
    track: np.ndarray | None = None
    target_size: np.ndarray | None = None
    ttc: np.ndarray | None = None
    category: tuple[str, ...] = ()
    twin: str | None = None

    def label(self, file: str) -> dict:
        """An entry in the format of ``labels.json`` for this clip saved as ``file``.

        The optional per-frame fields ``track`` (``[x, y]`` or null), ``target_size`` and
        ``ttc`` (numbers or null), and ``category`` and ``twin``, appear only where the scene
        has them.
        """
        t, h, w = self.frames.shape
        label = {"file": file, "width": w, "height": h, "fps": self.fps, "frames": t,
                 "collision": self.collision, "onset_frame": self.onset_frame,
                 "contact_frame": self.contact_frame,
                 "center": list(self.center) if self.center else None,
                 "description": f"generated scene {self.name} {self.params}"}
        if self.track is not None:
            label["track"] = [None if not np.all(np.isfinite(p)) else
                              [round(float(p[0]), 3), round(float(p[1]), 3)] for p in self.track]
        for key in ("target_size", "ttc"):
            values = getattr(self, key)
            if values is not None:
                label[key] = [round(float(v), 4) if math.isfinite(v) else None for v in values]
        if self.category:
            label["category"] = list(self.category)
        if self.twin is not None:
            label["twin"] = self.twin
        return label


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
        For an iterable without frames (an empty array writes an empty video).
    """
    path = Path(path)
    if isinstance(frames, np.ndarray):
        h, w = frames.shape[1:3]
    else:
        frames = iter(frames)
        first = next(frames, None)
        if first is None:
            raise ValueError(f"no frames to write to {path}")
        h, w = first.shape[:2]
        frames = itertools.chain([first], frames)
    fourcc = cv2.VideoWriter_fourcc(*("MJPG" if path.suffix.lower() == ".avi" else "mp4v"))
    writer = cv2.VideoWriter(str(path), fourcc, fps, (w, h), isColor=True)
    if not writer.isOpened():
        raise OSError(f"cannot write video {path}")
    written = 0
    try:
        with quiet_writer():  # a failed write is raised once, below
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


def write_frames(frames: np.ndarray, directory: str | Path) -> list[Path]:
    """Write frames as numbered PNG files (lossless) and return their paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, frame in enumerate(frames):
        path = directory / f"frame_{i:05d}.png"
        if not cv2.imwrite(str(path), frame):
            raise OSError(f"cannot write {path}")
        paths.append(path)
    return paths
