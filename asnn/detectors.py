"""One factory for every detector: the ASNN model and the LGMD baselines.

The models are imported when one is made, so that :data:`MODELS` and
:func:`available_cores` cost a process that runs none (the command line's parser) neither
numba nor OpenCV."""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, Protocol

from .params import ASNNParams, preset

if TYPE_CHECKING:
    import numpy as np

    from .baselines import LGMD1Params, LGMD2Params
    from .response import Response

__all__ = ["Detector", "MODELS", "available_cores", "make_detector", "responses"]

MODELS = ("asnn", "lgmd1", "lgmd2")


class Detector(Protocol):
    """What every model offers: one object per stream."""

    min_side: int  # the smallest height and width of a frame it takes

    def step(self, frame: np.ndarray, t: float | None = None) -> Response: ...

    def reset(self) -> None: ...


def make_detector(model: str = "asnn",
                  preset_name: str | ASNNParams | LGMD1Params | LGMD2Params | None = None,
                  **options) -> Detector:
    """Build a detector by name.

    Parameters
    ----------
    model : {'asnn', 'lgmd1', 'lgmd2'}
    preset_name : str, ASNNParams, LGMD1Params or LGMD2Params, optional
        ASNN preset, by name or as parameters (a name or ASNNParams is ignored by the LGMD
        models, which take their own parameters here, or as ``params=``); None means
        ``default``.
    **options
        Passed to the detector's constructor (for ASNN, e.g. ``record_maps``; for an LGMD
        model, ``params``).

    Raises
    ------
    ValueError
        For an unknown model or preset, or an LGMD model's parameters given twice.
    TypeError
        For parameters of another model than ``model``'s (LGMD1Params for ``lgmd2``).
    """
    if model == "asnn":
        from .model import ASNN

        if not (preset_name is None or isinstance(preset_name, (str, ASNNParams))):
            raise TypeError(f"asnn takes a preset's name or ASNNParams, not "
                            f"{type(preset_name).__name__}")
        params = (preset_name if isinstance(preset_name, ASNNParams)
                  else preset(preset_name or "default"))
        return ASNN(params, **options)
    if model in ("lgmd1", "lgmd2"):
        from . import baselines

        params_class = baselines.LGMD1Params if model == "lgmd1" else baselines.LGMD2Params
        if isinstance(preset_name, params_class):  # the baseline's own parameters
            if "params" in options:
                raise ValueError(f"{model}'s parameters given twice (preset_name and params)")
            options["params"] = preset_name
        elif isinstance(preset_name, str):
            preset(preset_name)  # ignored, but a misspelt name is still an error
        elif preset_name is not None and not isinstance(preset_name, ASNNParams):
            raise TypeError(f"{model} takes {params_class.__name__} (or params=...), not "
                            f"{type(preset_name).__name__}")

        asnn_only = sorted(set(options) & {"record_maps", "record_tracks", "optimised",
                                           "threads"})
        if asnn_only:
            raise ValueError(f"{', '.join(asnn_only)} apply to the ASNN model only, not {model}")
        return (baselines.LGMD1 if model == "lgmd1" else baselines.LGMD2)(**options)
    raise ValueError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")


def responses(detector: Detector, timed_frames: Iterable[tuple[float | None, np.ndarray]]
              ) -> Iterator[Response]:
    """The detector's responses to ``(t, frame)`` pairs, in order: its ``stream`` where it has
    one (:meth:`asnn.model.ASNN.stream`, which uses the model's threads), else ``step`` for
    each frame.

    Parameters
    ----------
    detector : Detector
        An ASNN model or an LGMD baseline (:func:`make_detector`), at the start of its stream
        or where the frames go on from.
    timed_frames : iterable of (float or None, ndarray)
        Each frame with its time in seconds (None: the detector's ``dt`` a frame).

    Yields
    ------
    Response
        One per frame, in order.
    """
    stream = getattr(detector, "stream", None)
    if stream is not None:
        yield from stream(timed_frames)
        return
    for t, frame in timed_frames:
        yield detector.step(frame, t)


def available_cores() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)
