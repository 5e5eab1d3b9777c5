"""The camera: frames of a file, a device, a stream URL or a generated scene, published on Zenoh.

Frames go to ``<prefix>/<robot>/frame``, best effort (congestion control drop, lowest data
priority): a late frame is worth less than the next one. ``seq`` counts from 0 and keeps
increasing across ``--loop`` repetitions; ``stamp`` is the wall-clock time of capture.

Optionally (``preview_hz`` > 0), a small jpeg thumbnail of the current frame goes to
``<prefix>/<robot>/preview`` a few times a second for dashboards (docs/contract.md), with the
same best-effort delivery as frames.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np
import zenoh

from asnn.stimuli import SCENE_NAMES, make_scene
from asnn.stimuli.suite import SUITE_CASES, make_case
from asnn.io.video import VideoError, open_video, read_frames

from . import keys
from .messages import FORMATS, Frame, Preview, encode

__all__ = ["FRAME_QOS", "PREVIEW_HZ", "PREVIEW_WIDTH", "Source", "SourceError", "open_source",
           "publish_frames"]

log = logging.getLogger("asnn.camera")

FRAME_QOS = dict(congestion_control=zenoh.CongestionControl.DROP,
                 priority=zenoh.Priority.DATA_LOW, reliability=zenoh.Reliability.BEST_EFFORT)
SYNTHETIC = "synthetic:"
PREVIEW_HZ = 2.0     # thumbnails per second on <prefix>/<robot>/preview (0: none)
PREVIEW_WIDTH = 160  # thumbnail width in pixels (never scaled up)


class SourceError(OSError):
    """A source that cannot be opened."""


@dataclass
class Source:
    """Frames (gray or BGR uint8) and their nominal rate.

    ``frames()`` yields one pass over the source; ``live`` sources (devices, URLs) cannot be
    replayed and are paced by their own capture.
    """

    name: str
    fps: float
    live: bool
    _open: object

    def frames(self) -> Iterator[np.ndarray]:
        return self._open()


def open_source(spec: str) -> Source:
    """Open ``FILE``, ``DEVICE_INDEX`` (an integer), ``URL`` (``scheme://...``) or
    ``synthetic:SCENE`` (one of ``asnn.stimuli.SCENE_NAMES``, 128x128, 20 fps, or a case of the
    labelled suite, ``asnn.stimuli.suite.SUITE_CASES``).

    Raises
    ------
    SourceError
        If the source does not exist or yields no frame.
    """
    if spec.startswith(SYNTHETIC):
        name = spec[len(SYNTHETIC):]
        if name in SCENE_NAMES:
            scene = make_scene(name)
        elif name in SUITE_CASES:
            scene = make_case(name)
        else:
            raise SourceError(f"unknown scene {name!r}; choose one of {', '.join(SCENE_NAMES)} "
                              "or a suite case (asnn scene --list)")
        return Source(spec, scene.fps, False, lambda: iter(scene.frames))
    if spec.isdigit() or "://" in spec:
        target = int(spec) if spec.isdigit() else spec
        cap = cv2.VideoCapture(target)
        if not cap.isOpened():
            raise SourceError(f"cannot open capture source {spec!r}")
        fps = cap.get(cv2.CAP_PROP_FPS)
        fps = float(fps) if fps and np.isfinite(fps) and 0 < fps <= 240 else 20.0
        return Source(spec, fps, True, lambda: read_frames(cap))
    try:
        clip = open_video(spec)
    except VideoError as exc:
        raise SourceError(str(exc)) from None
    return Source(spec, clip.fps, False, lambda: iter(clip))


def publish_frames(session: zenoh.Session, robot: str, source: Source, *,
                   prefix: str = keys.DEFAULT_PREFIX, fps: float | None = None,
                   loop: bool = False, format: str = "gray8", wait: float = 0.0,
                   stop: threading.Event | None = None, max_frames: int | None = None,
                   preview_hz: float = PREVIEW_HZ, preview_width: int = PREVIEW_WIDTH) -> int:
    """Publish the source's frames paced at ``fps`` (default: the source's rate).

    ``wait``: seconds to wait, at most, for a subscriber (a worker) before the first frame.
    ``preview_hz``: thumbnails (``preview_width`` pixels wide) per second on the preview key,
    at most one per frame; 0 publishes none.
    Returns the number of frames published. Ends at the end of the source unless ``loop``
    (a live source is never replayed), when ``stop`` is set, or after ``max_frames``.
    """
    if format not in FORMATS:
        raise ValueError(f"unknown frame format {format!r}; choose one of {', '.join(FORMATS)}")
    rate = float(fps or source.fps)
    if not rate > 0:
        raise ValueError(f"frame rate must be positive, got {rate}")
    if not preview_hz >= 0 or preview_width < 1:
        raise ValueError(f"need preview_hz >= 0 and preview_width >= 1, got {preview_hz}, "
                         f"{preview_width}")
    period = 1.0 / rate
    stop = stop or threading.Event()
    key = keys.frame_key(robot, prefix)
    publisher = session.declare_publisher(key, **FRAME_QOS)
    previews = (session.declare_publisher(keys.preview_key(robot, prefix), **FRAME_QOS)
                if preview_hz > 0 else None)
    next_preview = time.monotonic()
    try:
        deadline = time.monotonic() + wait
        while not publisher.matching_status and time.monotonic() < deadline and not stop.is_set():
            time.sleep(0.05)
        if wait and not publisher.matching_status:
            log.warning("no subscriber on %s after %.1f s; publishing anyway", key, wait)
        log.info("camera %s: %s at %.1f fps as %s on %s", robot, source.name, rate, format, key)
        seq = 0
        next_time = time.monotonic()
        while not stop.is_set():
            for image in source.frames():
                if stop.is_set() or (max_frames is not None and seq >= max_frames):
                    return seq
                now = time.monotonic()
                if source.live:  # paced by its capture; --fps only thins it out
                    if fps and now < next_time:
                        continue
                    next_time = max(next_time + period, now) if fps else now
                else:
                    if next_time > now:
                        if stop.wait(next_time - now):
                            return seq
                    elif now - next_time > period:  # fell behind: do not burst to catch up
                        next_time = now
                    next_time += period
                frame = Frame.from_image(np.ascontiguousarray(image), seq=seq,
                                         stamp=time.time(), format=format)
                publisher.put(encode(frame))
                if previews is not None and time.monotonic() >= next_preview:
                    next_preview = max(next_preview + 1.0 / preview_hz, time.monotonic())
                    try:
                        previews.put(encode(Preview.from_frame_image(
                            image, seq=seq, stamp=frame.stamp, width=preview_width)))
                    except Exception:  # a thumbnail is never worth losing the frames over
                        log.exception("camera %s: preview of frame %d failed", robot, seq)
                seq += 1
            if not loop or source.live or seq == 0:
                break
        return seq
    finally:
        publisher.undeclare()
        if previews is not None:
            previews.undeclare()
