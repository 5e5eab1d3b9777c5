"""Reading ahead and writing behind on threads of their own, in order.

``asnn detect`` steps the model on the main thread while frames are decoded ahead of it
(:func:`read_ahead`) and results are formatted and written behind it (:class:`WriteBehind`), so
that decoding, output and the model use the machine's cores at once. Both keep the order of the
items and a bounded number of them in flight, and hand an exception raised on their thread to
the main thread at the place it happened, so results are exactly those of a single loop. Video
decoding (OpenCV) and the model's kernels release the GIL; formatting JSON does not, but costs
little.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterable, Iterator
from typing import Generic, TypeVar

__all__ = ["WriteBehind", "read_ahead"]

T = TypeVar("T")
_END = object()


def read_ahead(items: Iterable[T], depth: int = 8) -> Iterator[T]:
    """Iterate ``items`` on a thread of its own, at most ``depth`` items ahead of the consumer.

    An exception raised by ``items`` is raised by this iterator after the items before it.
    Closing the iterator early (``break``, garbage collection) stops the thread.
    """
    if depth < 1:
        raise ValueError(f"depth must be at least 1, got {depth}")
    buffer: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def offer(entry) -> bool:
        while not stop.is_set():
            try:
                buffer.put(entry, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for item in items:
                if not offer((item, None)):
                    return
        except BaseException as exc:  # handed to the consumer, in order
            offer((_END, exc))
            return
        offer((_END, None))

    thread = threading.Thread(target=produce, daemon=True, name="asnn-read-ahead")
    thread.start()
    try:
        while True:
            item, error = buffer.get()
            if item is _END:
                if error is not None:
                    raise error
                return
            yield item
    finally:
        stop.set()
        thread.join(timeout=5)


class WriteBehind(Generic[T]):
    """Call ``write(item)`` for every :meth:`put` item on a thread of its own, in order.

    At most ``depth`` items wait; :meth:`put` blocks beyond. An exception raised by ``write``
    stops the writing: the next :meth:`put` or :meth:`close` raises it (the items before it
    were written). Use as a context manager: leaving it waits until every item is written.
    """

    def __init__(self, write: Callable[[T], None], depth: int = 4):
        if depth < 1:
            raise ValueError(f"depth must be at least 1, got {depth}")
        self._write = write
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._consume, daemon=True,
                                        name="asnn-write-behind")
        self._thread.start()

    def __enter__(self) -> WriteBehind[T]:
        return self

    def __exit__(self, *exc) -> None:
        self.close(raise_error=exc[0] is None)

    def _consume(self) -> None:
        while True:
            item = self._queue.get()
            if item is _END:
                return
            if self._error is not None:
                continue  # drain: put() must never block on a writer that gave up
            try:
                self._write(item)
            except BaseException as exc:
                self._error = exc

    def put(self, item: T) -> None:
        """Queue an item; raises the writer's exception if it failed."""
        if self._error is not None:
            raise self._error
        self._queue.put(item)

    def close(self, raise_error: bool = True) -> None:
        """Wait until every queued item is written; raise the writer's exception, if any."""
        if self._thread.is_alive():
            self._queue.put(_END)
            self._thread.join()
        if raise_error and self._error is not None:
            raise self._error
