"""A model's step held inside on another thread, for the tests of one stream, one thread."""

from __future__ import annotations

import contextlib
import threading


@contextlib.contextmanager
def step_held_inside(model, method: str, frame):
    """Within the block, another thread's ``model.step(frame)`` waits inside ``model.method``
    (an instance attribute wrapped for the block); on leaving, it goes on and is joined."""
    inside, release = threading.Event(), threading.Event()
    original = getattr(model, method)

    def held(*args):
        inside.set()
        release.wait(10)
        return original(*args)

    setattr(model, method, held)
    first = threading.Thread(target=model.step, args=(frame,))
    first.start()
    try:
        assert inside.wait(10)
        yield
    finally:
        release.set()
        first.join(10)
        delattr(model, method)
