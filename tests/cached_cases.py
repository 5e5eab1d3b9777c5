"""The suite's cases as the tests of the model and the evaluation read them: each rendered once a
session and handed out as a copy of its own.

A drive takes half a second or more to render, and the modules that read cases read 95 of them
221 times, one of them 13 times. The generator's own tests (tests/test_stimuli.py) render
afresh with :func:`asnn.stimuli.suite.make_case`: they check that two renderings agree.
"""

from __future__ import annotations

import copy
import functools

from asnn.stimuli import suite
from asnn.stimuli.scene import Scene

__all__ = ["make_case"]

#: renderings kept: some hundreds of megabytes of frames at most
KEPT = 64


@functools.lru_cache(maxsize=KEPT)
def _rendered(name: str, variant: int, driving_size: tuple[int, int] | None,
              scale: float | None) -> Scene:
    return suite.make_case(name, variant, driving_size, scale)


def make_case(name: str, variant: int = 0, driving_size: tuple[int, int] | None = None,
              scale: float | None = None) -> Scene:
    """:func:`asnn.stimuli.suite.make_case`, rendered once a session: a deep copy of that
    rendering, which the test may change as it likes."""
    return copy.deepcopy(_rendered(name, variant, driving_size, scale))
