"""Perturbed clips: is a score robust to the camera, or luck? (``asnn eval --perturb``)

A detector's outcomes on a dozen real clips can hang on details of their pixels that another
camera would not reproduce. Each perturbation here changes the frames the way a different
camera or a different day would, and ``asnn eval CLIPS_DIR --perturb NAME`` (or ``asnn eval
--synthetic --perturb NAME``) scores the detectors on the perturbed frames with the same labels
(mirrored with the frames for ``mirror``): outcomes that survive every perturbation are the
ones a fleet can count on.

Every perturbation is deterministic (the noise is seeded by the frame's index; ``mpeg4`` as far
as checked, below) and keeps the frames' channels and uint8 type. ``half-size`` and
``double-size`` change their size, as a camera of half or twice the resolution would (the
labels' centres scaled with them; enlarging adds no detail, but the model's parameters in pixels
meet objects and motions twice as large); ``half-detail`` halves them and enlarges them back, so
that the model sees a half-resolution camera's detail at the clip's own pixel scale (and the
labels stay as they are): beside ``half-size`` it tells what in the loss at half size is the
detail and what the pixel sizes of the model's kernels;
``half-rate`` drops every second frame, as a camera running at half the frame rate (10 fps for
the generated suite, 15 fps for the 30 fps dashcam clips) would deliver the same scene, and maps
the labels' frames onto the frames kept.

Three families take their strength in their name, for a camera's own settings: ``jpegQ``
re-encodes every frame as JPEG at quality Q (1-100; ``jpeg90`` is the wire's, ``jpeg`` is
``jpeg30``), ``gainG`` scales the brightness by G (0.1-10, rounded and clipped as a camera's 8
bits would be; ``dim`` is ``gain0.6``) and ``noiseS`` adds Gaussian sensor noise of S gray levels
(0.1-50; ``noise`` is ``noise4``): a camera raises its gain, and its noise, as the light falls.

Every perturbation but two changes each frame on its own (:func:`perturb_frame`). ``half-rate``
and ``mpeg4`` take the clip as a whole (:func:`perturbed`): ``mpeg4`` re-encodes it with an
inter-frame codec, MPEG-4 Part 2 through OpenCV's FFmpeg writer, as a camera's video file is
coded: blocks that did not change are skipped (copied exactly from the previous decoded frame),
moving ones are predicted from it and their residual quantised, and every 12th frame is coded on
its own. It keeps the frames' number, times, size, channels and uint8 type, and the labels as they
are; two encodings of the same frames have given the same frames (:func:`reencoded`).
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Iterable, Iterator, Mapping

import cv2
import numpy as np

from ..io.images import JPEG_QUALITY as WIRE_JPEG_QUALITY
from ..io.video import quiet_opencv
from ..stimuli.effects import camera_rig, jpeg, sensor_noise, wiper
from .options import FAMILIES, PERTURBATIONS

__all__ = ["FAMILIES", "PERTURBATIONS", "check_perturbation", "delivered_period", "describe",
           "keeps_frames", "perturb_frame", "perturbed", "perturb_label", "reencoded"]

# the perturbations that drop frames instead of changing them: frame k kept is frame step * k
_RATE_STEP = {"half-rate": 2}
_PER_FRAME = ("track", "target_size", "ttc")  # label fields with one entry per frame
_SCALE = {"half-size": 0.5, "double-size": 2.0}  # the perturbations that resize the frames
NOISE_SIGMA = 4.0
JPEG_QUALITY = {"jpeg": 30, "jpeg90": WIRE_JPEG_QUALITY}  # jpeg90: as the camera sends frames
DIM_GAIN = 0.6
WIPER_GRAY = 20.0  # the blade's rubber, dark against the view
# the perturbations that code a clip's frames together (mpeg4: reencoded)
_CLIP_LEVEL = ("mpeg4",)
# mpeg4: MPEG-4 Part 2 ('mp4v'; OpenCV's writer has no H.264 here). Its quality is OpenCV's, not
# ours: the FFmpeg writer takes no quality for it (VIDEOWRITER_PROP_QUALITY is refused, and
# OPENCV_FFMPEG_WRITER_OPTIONS does not reach the encoder: the file's size does not change), and
# fixes the quantiser's floor at 3, a key frame every 12 frames and a budget of 2 bits per pixel
# and frame that natural frames never reach, so the quantiser stays near 3. That resembles a
# consumer camera's file: on the real 432x240 clips it spends 0.16-0.41 bits per pixel and frame,
# where their own MPEG-4 files spend 0.18-0.23 and a 1080p30 dashcam at 12-16 Mbit/s in H.264
# 0.19-0.26; it changes their pixels by 0.6-2.2 gray levels on average. At this quality it keeps
# most sensor noise (the suite's noise cases: 4-15 % of the pixels copied from frame to frame,
# the real clips' own files 45-82 %): a file at a lower bit rate would copy more of it.
CODEC_FOURCC = "mp4v"
CODEC_FPS = 30.0  # the rate written in the file: the decoded frames do not depend on it


_FAMILY = re.compile(r"(jpeg)([0-9]{1,3})|(gain|noise)([0-9]{1,2}(?:\.[0-9]{1,4})?)")
GAIN_RANGE = (0.1, 10.0)
NOISE_RANGE = (0.1, 50.0)


# the named perturbations that are members of a family
_MEMBERS = {**{name: f"jpeg{quality}" for name, quality in JPEG_QUALITY.items()},
            "dim": f"gain{DIM_GAIN:g}", "noise": f"noise{NOISE_SIGMA:g}"}


def _strength(name: str) -> tuple[str, float] | None:
    """``('jpeg', Q)``, ``('gain', G)`` or ``('noise', S)`` for a family's name within its
    range, or for a named member of one (``jpeg``, ``jpeg90``, ``dim``, ``noise``), else None."""
    match = _FAMILY.fullmatch(_MEMBERS.get(name, name))
    if match is None:
        return None
    if match.group(1):
        quality = int(match.group(2))
        return ("jpeg", quality) if 1 <= quality <= 100 else None
    family, strength = match.group(3), float(match.group(4))
    low, high = GAIN_RANGE if family == "gain" else NOISE_RANGE
    return (family, strength) if low <= strength <= high else None


def check_perturbation(name: str | None) -> None:
    """Raise ValueError unless ``name`` is None, one of :data:`PERTURBATIONS` or of the
    :data:`FAMILIES` within its range (``jpeg80``, ``gain1.04``, ``noise2.5``)."""
    if name is not None and name not in PERTURBATIONS and _strength(name) is None:
        raise ValueError(f"unknown perturbation {name!r}; choose one of "
                         f"{', '.join(PERTURBATIONS)}, or jpegQ (quality Q, 1-100), gainG "
                         f"(brightness times G, {GAIN_RANGE[0]:g}-{GAIN_RANGE[1]:g}) or noiseS "
                         f"(S gray levels of noise, {NOISE_RANGE[0]:g}-{NOISE_RANGE[1]:g})")


def keeps_frames(name: str) -> bool:
    """Whether the perturbation ``name`` gives back every frame at its size and in its place
    (all but ``half-rate``, ``half-size`` and ``double-size``), so that what a detector reports
    on the perturbed frames is about the frames as given: one record per frame, in their
    pixels."""
    return name not in _RATE_STEP and name not in _SCALE


def delivered_period(fps: float, name: str | None) -> float:
    """The seconds between the frames the perturbation ``name`` delivers (None: none) of a
    clip at ``fps``: ``half-rate`` doubles the period."""
    return _RATE_STEP.get(name, 1) / fps


def describe(name: str) -> str:
    """What the perturbation ``name`` does, in words (the reports print it)."""
    check_perturbation(name)
    if name in PERTURBATIONS:
        return PERTURBATIONS[name]
    family, strength = _strength(name)
    if family == "jpeg":
        return f"every frame re-encoded as JPEG at quality {strength:g}"
    if family == "noise":
        return f"Gaussian sensor noise of {strength:g} gray levels on every pixel"
    return f"{strength:g} times the brightness, rounded and clipped to 8 bits"


def perturb_frame(frame: np.ndarray, name: str, index: int) -> np.ndarray:
    """The frame ``index`` of a clip (uint8, gray or colour) under the perturbation ``name``.

    Raises
    ------
    ValueError
        For an unknown perturbation, one that drops frames (``half-rate``) or codes the frames
        together (``mpeg4``: see :func:`perturbed`), or a frame that is not uint8.
    """
    check_perturbation(name)
    if name in _RATE_STEP:
        raise ValueError(f"{name!r} drops frames instead of changing one: apply it to a clip "
                         "with perturbed()")
    if name in _CLIP_LEVEL:
        raise ValueError(f"{name!r} codes a clip's frames together, each from the one before: "
                         "apply it to a clip with perturbed()")
    if frame.dtype != np.uint8:
        raise ValueError(f"perturbations take uint8 frames, got {frame.dtype}")
    if name == "mirror":
        return np.ascontiguousarray(frame[:, ::-1])
    if name in _SCALE:
        return _resized(frame, _SCALE[name])
    if name == "half-detail":
        return cv2.resize(_resized(frame, 0.5), frame.shape[1::-1],
                          interpolation=cv2.INTER_LINEAR)
    family = _strength(name)
    if family and family[0] == "jpeg":
        return jpeg(frame[None], family[1])[0]
    if name == "hood":
        covered, values = camera_rig(frame.shape[1::-1])
        changed = frame.astype(np.float64)
        changed[covered] = values[covered, None] if frame.ndim == 3 else values[covered]
    elif name == "wiper":
        blade = wiper(frame.shape[1::-1], index).astype(np.float64)
        if frame.ndim == 3:
            blade = blade[..., None]
        changed = frame * (1.0 - blade) + WIPER_GRAY * blade
    elif family and family[0] == "noise":
        changed = sensor_noise(frame.astype(np.float64), family[1], seed=index)
    else:  # dim, or gainG
        changed = frame * family[1]
    return np.clip(np.rint(changed), 0, 255).astype(np.uint8)


def _resized(frame: np.ndarray, factor: float) -> np.ndarray:
    """``frame`` at ``factor`` times its width and height: averaged down, or enlarged
    bilinearly."""
    h, w = frame.shape[:2]
    return cv2.resize(frame, (max(1, round(w * factor)), max(1, round(h * factor))),
                      interpolation=cv2.INTER_AREA if factor < 1 else cv2.INTER_LINEAR)


def perturbed(timed_frames: Iterable[tuple[float, np.ndarray]], name: str | None
              ) -> Iterator[tuple[float, np.ndarray]]:
    """``(t, frame)`` pairs with every frame perturbed (``name`` None: as they are), or, for a
    perturbation that drops frames, the frames kept with their own times; for ``mpeg4``, the
    clip re-encoded (:func:`reencoded`: no frame comes out before the last one went in)."""
    if name in _CLIP_LEVEL:
        yield from reencoded(timed_frames)
        return
    step = _RATE_STEP.get(name, 1)
    for index, (t, frame) in enumerate(timed_frames):
        if index % step:
            continue
        yield t, frame if name is None or step > 1 else perturb_frame(frame, name, index)


def reencoded(timed_frames: Iterable[tuple[float, np.ndarray]]
              ) -> Iterator[tuple[float, np.ndarray]]:
    """A clip's ``(t, frame)`` pairs through an inter-frame codec, with their own times: the
    frames are written to a temporary MPEG-4 Part 2 file (:data:`CODEC_FOURCC`) through OpenCV's
    FFmpeg writer, read back, and the file removed, also on an error or when the caller stops
    early.

    Gray frames stay gray (coded as luma with neutral chroma) and colour frames colour (BGR,
    coded as YUV 4:2:0: they come back about 2 gray levels darker on average, OpenCV's
    conversions not being each other's inverse), all uint8 and of their own size: a frame of odd
    width or height is padded by repeating its last column or row (the writer would cut it) and
    cropped back. Memory: one frame at a time and a float per frame; the clip is held coded, in
    the temporary folder (about 0.2-0.4 bits per pixel and frame), and nothing is yielded before
    the last frame is written. Two encodings of the same frames have given the same frames, in
    one process or two (checked on generated and real clips; FFmpeg does not promise it).

    Raises
    ------
    ValueError
        For a frame that is not uint8, gray or 3-channel, or not of the first frame's shape; when
        the writer cannot be opened; or when the file gives back another number of frames than
        went in.
    """
    fd, path = tempfile.mkstemp(prefix="asnn-mpeg4-", suffix=".mp4")
    os.close(fd)
    try:
        # a writer that fails (a full disk) would log a warning for every frame: the frames
        # missing when the file is read back are reported once, below
        with quiet_opencv():
            times, shape = _encoded(timed_frames, path)
        if not times:
            return
        height, width = shape[:2]
        capture = cv2.VideoCapture(path, cv2.CAP_FFMPEG)
        try:
            for count, t in enumerate(times):
                ok, frame = capture.read()
                if not ok:
                    raise ValueError(f"mpeg4: the re-encoded clip gave back {count} of its "
                                     f"{len(times)} frames")
                frame = frame[:height, :width]
                if len(shape) == 2:
                    frame = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
                yield t, np.ascontiguousarray(frame)
            if capture.grab():
                raise ValueError(f"mpeg4: the re-encoded clip gave back more than its "
                                 f"{len(times)} frames")
        finally:
            capture.release()
    finally:
        os.remove(path)


def _encoded(timed_frames: Iterable[tuple[float, np.ndarray]], path: str
             ) -> tuple[list[float], tuple[int, ...] | None]:
    """Write the frames to ``path`` (:func:`reencoded`); their times and the first one's shape."""
    times, shape, writer = [], None, None
    try:
        for t, frame in timed_frames:
            if frame.dtype != np.uint8:
                raise ValueError(f"perturbations take uint8 frames, got {frame.dtype}")
            if shape is None:
                shape = frame.shape
                if not (frame.ndim == 2 or (frame.ndim == 3 and shape[2] == 3)):
                    raise ValueError(f"mpeg4 takes gray or 3-channel frames, got shape {shape}")
                height, width = shape[:2]
                writer = cv2.VideoWriter(path, cv2.CAP_FFMPEG,
                                         cv2.VideoWriter_fourcc(*CODEC_FOURCC), CODEC_FPS,
                                         (width + width % 2, height + height % 2),
                                         frame.ndim == 3)
                if not writer.isOpened():
                    raise ValueError(f"mpeg4: OpenCV's FFmpeg writer cannot write "
                                     f"{CODEC_FOURCC!r} at {width}x{height}")
            elif frame.shape != shape:
                raise ValueError(f"mpeg4: a clip's frames change shape, {shape} to "
                                 f"{frame.shape}")
            if height % 2 or width % 2:
                frame = cv2.copyMakeBorder(frame, 0, height % 2, 0, width % 2,
                                           cv2.BORDER_REPLICATE)
            writer.write(np.ascontiguousarray(frame))
            times.append(t)
    finally:
        if writer is not None:
            writer.release()
    return times, shape


def perturb_label(label: Mapping, name: str | None) -> dict:
    """A clip's label for its perturbed frames: for ``mirror`` the centre and the per-frame
    ``track`` mirrored (x -> width - 1 - x; the label needs its ``width``); for one that resizes
    the frames, its size, centre, track and target sizes scaled; for one that drops frames, its
    frames, fps and per-frame lists on the frames kept; otherwise as it is.

    Raises
    ------
    ValueError
        For ``mirror`` on a label with a centre or track but no width.
    """
    label = dict(label)
    if name in _RATE_STEP:
        return _label_at_rate(label, _RATE_STEP[name])
    if name in _SCALE:
        return _label_at_scale(label, _SCALE[name])
    if name != "mirror" or (label.get("center") is None and not label.get("track")):
        return label
    if not label.get("width"):
        raise ValueError(f"{label.get('file', 'a label')}: mirroring its centre needs its width")
    right = float(label["width"]) - 1.0
    return _moved_points(label, lambda x, y: [right - x, y])


def _moved_points(label: dict, move) -> dict:
    """``label`` with its centre and per-frame track moved by ``move(x, y) -> [x, y]``."""
    if label.get("center") is not None:
        label["center"] = move(*label["center"])
    if label.get("track"):
        label["track"] = [None if point is None else move(*point) for point in label["track"]]
    return label


def _label_at_scale(label: dict, factor: float) -> dict:
    """The label of a clip whose frames are resized by ``factor``: its size, centre, per-frame
    track (pixel centres: ``x -> (x + 0.5) factor - 0.5``) and target sizes scaled."""
    for key in ("width", "height"):
        if label.get(key):
            label[key] = max(1, round(int(label[key]) * factor))
    _moved_points(label, lambda x, y: [(float(x) + 0.5) * factor - 0.5,
                                       (float(y) + 0.5) * factor - 0.5])
    if isinstance(label.get("target_size"), list):
        label["target_size"] = [None if v is None else float(v) * factor
                                for v in label["target_size"]]
    return label


def _label_at_rate(label: dict, step: int) -> dict:
    """The label of a clip of which every ``step``-th frame is kept (frame k is frame step * k).

    The onset moves to the first frame kept at or after it and the contact to the last kept at
    or before it, so the hit window never grows and a lead is never credited with time the
    clip did not show; per-frame lists keep the frames kept. Where no kept frame lies between
    them (onset and contact one odd frame), both move to the contact's: a window of one frame.
    """
    if label.get("fps"):
        label["fps"] = float(label["fps"]) / step
    if label.get("frames"):
        label["frames"] = -(-int(label["frames"]) // step)
    if label.get("onset_frame") is not None:
        label["onset_frame"] = -(-int(label["onset_frame"]) // step)
    if label.get("contact_frame") is not None:
        label["contact_frame"] = int(label["contact_frame"]) // step
        if label.get("onset_frame") is not None:
            label["onset_frame"] = min(label["onset_frame"], label["contact_frame"])
    for key in _PER_FRAME:
        if isinstance(label.get(key), list):
            label[key] = label[key][::step]
    return label
