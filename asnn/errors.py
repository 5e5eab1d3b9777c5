"""The model's errors, in a module of their own (no OpenCV, no numba), so that a process that
only catches them (the service's worker core, imported by the command line's parser) need not
load the model to name them."""

from __future__ import annotations

import contextlib
import sys
import warnings
from collections.abc import Callable, Iterator

__all__ = ["FrameError", "TimingWarning", "timing_warnings_to"]


class FrameError(ValueError):
    """A frame the model cannot take: wrong type, shape, range or size.

    Raised by a detector's ``step`` (:meth:`asnn.ASNN.step`, the LGMD baselines') before its
    state changes, for a frame that is not a numpy array (or is a masked one), is neither gray
    nor BGR, is smaller than the model's kernels or not the stream's size, is neither uint8 nor
    float, or holds floats outside [0, 1], NaN or infinities (:func:`asnn.frames.check_frame`);
    and for a frame time ``t`` that is not a number of seconds (a str, a bool) or is beyond a
    float's range (``10**400``), as :func:`asnn.frames.frame_time` refuses it. A ValueError:
    code that catches those catches it too.
    """


class TimingWarning(UserWarning):
    """Frame times the model cannot measure time with: it times those frames at ``params.dt``.

    Warned by :meth:`asnn.ASNN.step` (and :meth:`~asnn.ASNN.stream`) once per stream, when
    :data:`asnn.params.PERIOD_FRAMES` frames in a row come with a time ``t`` less than
    :data:`~asnn.params.MIN_FRAME_GAP_S` or more than :data:`~asnn.params.MAX_FRAME_GAP_S`
    after the previous one: a clock in milliseconds or nanoseconds, a camera slower than a
    frame a second, or a clock that stands still (a fast camera's, past the two frames at one
    instant the frame-rate ceiling holds as sent twice) or goes back. The responses go on,
    their expansion rates and time to contact off by as much as the clock is. Raised once the
    frame is stepped (where warnings are errors, the frame's response is then lost, the model
    stepped); from a :meth:`~asnn.ASNN.stream` with worker threads, which takes frames up to
    two ahead of the response it yields, with the response of a frame up to two before it
    (and where warnings are errors, the responses of the frames it had taken are lost with it,
    as in a stream left early). Silence it with :func:`warnings.filterwarnings` where that is
    meant (the service's worker logs the same itself, per robot).
    """


_PACKAGE = __name__.partition(".")[0]  # "asnn"


def _ours(frame) -> bool:
    """Whether the frame runs code of the asnn package, known by its module's name (a path
    is not: ``..`` in a sys.path entry, zipimport, a frozen application)."""
    name = frame.f_globals.get("__name__") or ""
    return name == _PACKAGE or name.startswith(_PACKAGE + ".")


def _warn_at_caller(message: str, category: type[Warning]) -> None:
    """Warn at the first line outside the asnn package on the way up the stack: the caller's
    line that stepped the model, through however many of asnn's own frames (a ``stream``
    inside :func:`asnn.detectors.responses` is one more than ``step``). Python 3.12's
    ``skip_file_prefixes``, by hand."""
    frame, level = sys._getframe(1), 2
    while frame is not None and _ours(frame):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, category, stacklevel=level)


@contextlib.contextmanager
def timing_warnings_to(tell: Callable[[str], None]) -> Iterator[None]:
    """Within the block, each :class:`TimingWarning` goes to ``tell(message)``, shown or not
    as a program says its own notes (Python's form names a file and line of asnn's and its
    code, read as a fault), and never raised, even where warnings are errors; every other
    warning as before. For a command's own notes (``asnn detect``, ``asnn eval``)."""
    with warnings.catch_warnings():
        warnings.simplefilter("always", TimingWarning)
        shown = warnings.showwarning

        def show(message, category, *rest, **keywords):
            if issubclass(category, TimingWarning):
                tell(str(message))
            else:
                shown(message, category, *rest, **keywords)

        warnings.showwarning = show
        yield
