"""Loading the model's numba kernels before the first frame needs them: :func:`compile_kernels`.

numba compiles a kernel when it is first called, or loads it from its on-disk cache; either way
the first frame that reaches a stage would wait for it (seconds on a fresh install). Long-running
processes (the worker, ``asnn detect``, the benchmarks) call :func:`compile_kernels` first: it
steps a model of each preset over a small generated approach, and calls the kernels that clip
does not reach.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from . import _fast
from .approach import CameraRig
from .approach.looming import Expansion, refined_expansion, region_expansion, shrunk_mask
from .approach.motion_layers import motion_layers
from .frames import LEVELS
from .model import ASNN
from .params import ASNNParams

__all__ = ["compile_kernels"]


def _warmup_clip(min_side: int) -> np.ndarray:
    """The frames :func:`compile_kernels` steps a model over: a small off-centre looming disk,
    so that every stage, including the clustering, has work; 64x64, or as large as the
    smallest frame the model takes (``min_side``: a preset with larger kernels)."""
    from .stimuli import make_scene

    side = max(64, min_side)
    return make_scene("looming", size=(side, side), start=2, stop=12,
                      center=(30.0 * side / 64, 33.0 * side / 64)).frames


def compile_kernels(presets: Iterable[str | ASNNParams] = ("default", "reference"),
                    threads: int = 1, straightforward: bool = False) -> None:
    """Compile the optimised step's numba kernels, or load them from numba's on-disk cache
    (seconds on a fresh install, milliseconds afterwards).

    Long-running processes call it before they take their first frame, so that frame does not
    wait for the compiler; and numba loads a kernel from its cache only when it is first
    called, so without it the first frames that need a stage (the first object, the first
    looming fit) wait for its kernels.

    Parameters
    ----------
    presets : iterable of str or ASNNParams
        The presets (by name or as parameters) whose kernels to load (default: both
        precisions, float32 and float64).
    threads : int
        As the models that will run (``ASNN(..., threads=N)``): with more than 1, the kernel of
        the model's worker threads too.
    straightforward : bool
        The straightforward form's too (``ASNN(..., optimised=False)``): it runs the objects'
        kernels in float64, which a float32 preset's optimised form never calls (a benchmark
        of it would otherwise time their compiling).
    """
    forms = (True, False) if straightforward else (True,)
    for name, optimised in ((name, form) for name in presets for form in forms):
        with ASNN(name, threads=threads, optimised=optimised) as model:
            for _ in model.stream((None, frame) for frame in _warmup_clip(model.params.min_side)):
                pass
            # the looming fit of boxes larger than its grid, which the clip's objects are not:
            # area-averaged in the fit's kernel, and by whole factors (cv2.resize)
            flat = np.zeros((128, 128), model.dtype)
            for box in ((0, 0, 90, 80), (0, 0, 128, 64)):
                region_expansion(flat, flat, box, flat)
            # the refined time to contact's steps (refined_ttc), first called late in an approach
            start = Expansion(0.0, 0.0, 0.1, 0.0, 1.0)
            for background in (None, flat):
                refined_expansion(flat, flat, (0, 0, 90, 80), start, background=background)
            # the motion layers' kernel, which the clip (a still camera) never reaches
            texture = np.random.default_rng(0).random((64, 64)).astype(model.dtype)
            motion_layers(texture, texture, (0, 0, 64, 64))
            # the objects' summed motion vectors, first read when an object approaches (on the
            # maps' own arrays: numba compiles a kernel for each layout)
            if optimised and model.approach is not None:
                maps = _fast.workspace(model.previous.shape, model.dtype).maps
                pixel = np.zeros(1, np.int64)
                _fast.MotionVectors(maps.r, maps.v).sums(pixel, pixel, pixel, 1)
            # the whole-factor averages of frames 320 pixels wide (the fits' grid, the repeat
            # test's blocks), which the clip's small frames do not reach
            for factor in (5, 8):
                _fast.block_means(np.zeros((factor, factor), model.dtype), (1, 1))
            # frames wider than max_width, shrunk as they are taken
            _fast.shrunk_luminance(np.zeros((16, 20), np.uint8), (15, 12), LEVELS, model.dtype)
            # the camera rig's edge test and its mask, which a stream first needs after 20
            # frames with its own hood in view (a still edge at the frames' bottom)
            if model.approach is not None:
                hood = np.zeros((16, 16), model.dtype)
                hood[12:] = 1.0
                rig = CameraRig()
                for _ in range(21):
                    rig.update(hood, hood)
                # its mask shrunk by a whole factor (the surface watch's grid)
                if rig.mask is not None:
                    shrunk_mask(rig.mask, (8, 8))
