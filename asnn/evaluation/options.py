"""The evaluation's named choices and defaults, data only (no OpenCV, numba or model): the
command line's parser lists them in ``asnn eval -h`` and ``asnn detect -h`` without loading the
tooling, which imports them from here (:mod:`~asnn.evaluation.perturb`,
:mod:`~asnn.evaluation.heldout`, :mod:`~asnn.evaluation.runs`,
:mod:`~asnn.evaluation.scoring`)."""

from __future__ import annotations

__all__ = ["DEFAULT_DETECTORS", "EARLY_TOLERANCE_S", "FAMILIES", "PERTURBATIONS", "TIE_BREAKS",
           "WARMUP_FRAMES"]

# the detectors an evaluation runs unless told otherwise (asnn eval --detectors)
DEFAULT_DETECTORS = ("asnn", "asnn:reference", "lgmd1", "lgmd2")
# scoring: frames ignored at a clip's start, and how long before the labelled onset a first
# warning still counts as a hit (asnn eval --warmup, --early-tolerance)
WARMUP_FRAMES = 5
EARLY_TOLERANCE_S = 0.5

# name -> what it does (asnn eval -h lists them)
PERTURBATIONS = {
    "noise": "Gaussian sensor noise of 4 gray levels on every pixel",
    "jpeg": "every frame re-encoded as JPEG at quality 30",
    "jpeg90": "every frame re-encoded as JPEG at quality 90, as asnn camera --format jpeg sends "
              "frames",
    "dim": "0.6 times the brightness (an under-exposed camera)",
    "mirror": "every frame flipped left to right (the labels' centres with it)",
    "hood": "a dashcam's own hood along the bottom and a timestamp overlay, still in every frame",
    "wiper": "a windscreen wiper's blurred blade sweeping across the view and back every 40 "
             "frames (rain: 2 s at 20 fps)",
    "half-size": "every frame averaged down to half its width and height (a camera of half the "
                 "resolution; the labels' centres with it)",
    "double-size": "every frame enlarged to twice its width and height, bilinearly (the labels' "
                   "centres with it)",
    "half-detail": "every frame averaged down to half its width and height and enlarged back to "
                   "its size, bilinearly (a camera of half the resolution whose frames are "
                   "upscaled before the model; the labels as they are)",
    "half-rate": "every second frame dropped, as a camera at half the frame rate would deliver "
                 "them; the labels follow the frames kept",
    "mpeg4": "every clip re-encoded by an inter-frame codec (MPEG-4 Part 2 through OpenCV's "
             "FFmpeg writer, as a camera's video file is: unchanged blocks copied, moving ones "
             "predicted and their residual quantised)",
}

# the families named with their strength: jpegQ (quality Q), gainG (brightness times G) and
# noiseS (S gray levels of noise)
FAMILIES = {"jpegQ": "every frame re-encoded as JPEG at quality Q (1-100)",
            "gainG": "the brightness times G (0.1-10), rounded and clipped to 8 bits",
            "noiseS": "Gaussian sensor noise of S gray levels (0.1-50) on every pixel"}

# how grid points that tie on hits and false alarms are told apart (heldout.selection_key); the
# first rewards thresholds that warn more, so the held-out figures are given with each
TIE_BREAKS = {
    "warning-frames": "more warning frames inside the hit windows than outside them, then the "
                      "first in grid order",
    "grid": "the first in grid order (smaller thresholds first)",
    "suite": "more hits minus false alarms on the generated suite, then fewer false alarms "
             "there, then the first in grid order",
}
