"""One factory for every detector: the ASNN model and the baselines it is compared with.

A baseline is registered in one place, :data:`BASELINES`; :data:`MODELS`, ``asnn detect``,
``asnn worker`` and ``asnn bench --model``, ``asnn eval --detectors`` and a run's reports all
read it. The models are imported when one is made, so that :data:`MODELS` and
:func:`available_cores` cost a process that runs none (the command line's parser) neither
numba nor OpenCV."""

from __future__ import annotations

import importlib
import os
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, NamedTuple, Protocol

from .params import ASNNParams, preset

if TYPE_CHECKING:
    import numpy as np

    from .baselines import LGMD1Params, LGMD2Params
    from .response import Response

__all__ = ["BASELINES", "Baseline", "Detector", "MODELS", "available_cores", "baseline_classes",
           "make_detector", "responses"]


class Baseline(NamedTuple):
    """Where a baseline's class and the class of its parameters live (names, so that the
    parser imports no model), and what it is, for a report's reader."""

    module: str
    cls: str
    params: str
    description: str


# Every baseline, by the name the command line and the detector specs give it. A new one is one
# entry here (CONTRIBUTING.md, "A new baseline"): its class is a Detector, built as
# ``cls(params=None, **fields)``, whose parameters are a frozen pydantic model with a ``dt``
# field, the frame period ``asnn detect`` and ``asnn eval`` set from the clip.
BASELINES = {
    "lgmd1": Baseline("asnn.baselines", "LGMD1", "LGMD1Params", "LGMD1-1 (Yue & Rind 2006)"),
    "lgmd2": Baseline("asnn.baselines", "LGMD2", "LGMD2Params", "LGMD1-2 (Fu et al. 2018)"),
}
MODELS = ("asnn", *BASELINES)


def baseline_classes(model: str) -> tuple[type, type]:
    """A baseline's class and the class of its parameters.

    Raises
    ------
    ValueError
        If ``model`` is not in :data:`BASELINES`.
    """
    if model not in BASELINES:
        raise ValueError(f"unknown baseline {model!r}; choose one of {', '.join(BASELINES)}")
    entry = BASELINES[model]
    module = importlib.import_module(entry.module)
    return getattr(module, entry.cls), getattr(module, entry.params)


class Detector(Protocol):
    """What every model offers: one object per stream.

    A baseline's class also has ``params`` (its frozen pydantic parameters, ``dt`` among
    them: the frame period in seconds) and is built as ``cls(params=None, **fields)``; one
    stream at a time (a second thread's step is refused), and a ``t`` that is not a number
    of seconds is a :class:`~asnn.errors.FrameError`, as the ASNN's is.
    """

    min_side: int  # the smallest height and width of a frame it takes

    def step(self, frame: np.ndarray, t: float | None = None) -> Response: ...

    def reset(self) -> None: ...


def make_detector(model: str = "asnn",
                  preset_name: str | ASNNParams | LGMD1Params | LGMD2Params | None = None,
                  **options) -> Detector:
    """Build a detector by name.

    Parameters
    ----------
    model : str
        One of :data:`MODELS`: ``asnn`` or a baseline of :data:`BASELINES`.
    preset_name : str, ASNNParams or a baseline's parameters, optional
        ASNN preset, by name or as parameters (a name or ASNNParams is ignored by a baseline,
        which takes its own parameters here, or as ``params=``); None means ``default``.
    **options
        Passed to the detector's constructor (for ASNN, e.g. ``record_maps``; for a baseline,
        ``params`` or its fields).

    Raises
    ------
    ValueError
        For an unknown model or preset, or a baseline's parameters given twice.
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
    if model in BASELINES:
        cls, params_class = baseline_classes(model)
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
        return cls(**options)
    raise ValueError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")


def responses(detector: Detector, timed_frames: Iterable[tuple[float | None, np.ndarray]]
              ) -> Iterator[Response]:
    """The detector's responses to ``(t, frame)`` pairs, in order: its ``stream`` where it has
    one (:meth:`asnn.model.ASNN.stream`, which uses the model's threads), else ``step`` for
    each frame.

    Parameters
    ----------
    detector : Detector
        An ASNN model or a baseline (:func:`make_detector`), at the start of its stream
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
