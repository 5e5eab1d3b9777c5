"""A generated clip with its ground truth."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Scene"]


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
