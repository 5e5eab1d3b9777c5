"""Threads of one model (private; used by :class:`asnn.model.ASNN` with ``threads`` > 1).

:class:`Worker` runs calls in order on a thread of its own and hands their results, or their
exceptions, back to the thread that waits for them. :class:`BandedFront` computes
:func:`asnn._fast.front` in bands of rows, one per thread, and moves the bands' borders from
frame to frame so that the workers are done about when the calling thread needs their bands:
every pixel is computed the same way whatever the bands, so where the borders lie changes
nothing in the results, only in the time. The numba kernels release the GIL, so the bands do
run at once.
"""

from __future__ import annotations

import queue
import threading
import time
from collections import deque

import numpy as np

from . import _fast

__all__ = ["Task", "Worker", "BandedFront"]


class Task:
    """A call submitted to a :class:`Worker`; :meth:`wait` returns its result or raises its
    exception. ``started`` is its ``time.perf_counter()`` time, ``cpu`` the processor time
    the call took (None until it is done)."""

    __slots__ = ("_call", "_done", "_result", "_error", "started", "cpu")

    def __init__(self, call):
        self._call = call
        self._done = threading.Lock()
        self._done.acquire()  # released when the call has returned or raised
        self._result = self._error = None
        self.started = 0.0
        self.cpu: float | None = None

    def run(self) -> None:
        self.started = time.perf_counter()
        cpu = time.thread_time()
        try:
            self._result = self._call()
        except BaseException as exc:  # handed to the waiting thread
            self._error = exc
        finally:
            self._call = None  # no reference to the model once done
            self.cpu = time.thread_time() - cpu
            self._done.release()

    def wait(self):
        """Block until the call is done; return its result or raise its exception."""
        with self._done:
            pass
        if self._error is not None:
            raise self._error
        return self._result

    def join(self) -> None:
        """Block until the call is done, ignoring its outcome."""
        with self._done:
            pass


class Worker:
    """A daemon thread that runs submitted calls one after the other, in order."""

    def __init__(self, name: str):
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._serve, args=(self._queue,), daemon=True,
                                        name=name)
        self._thread.start()

    @staticmethod
    def _serve(tasks: queue.SimpleQueue) -> None:
        while (task := tasks.get()) is not None:
            task.run()

    def submit(self, call) -> Task:
        """Queue ``call()``; returns its :class:`Task`.

        Raises
        ------
        RuntimeError
            If the worker was closed.
        """
        if not self._thread.is_alive():
            raise RuntimeError("the model's worker thread has stopped (the model was closed)")
        task = Task(call)
        self._queue.put(task)
        return task

    def close(self) -> None:
        """Stop the thread once the calls queued before have run."""
        self._queue.put(None)


class _Pass:
    """One frame's fused pass in flight (see :class:`BandedFront`)."""

    __slots__ = ("p", "stages", "other", "versions", "maps", "borders", "tasks", "done",
                 "submitted", "overlapped", "own")

    def __init__(self, p, stages, other, versions, maps, borders, tasks, done, submitted,
                 overlapped):
        self.p, self.stages, self.other, self.versions = p, stages, other, versions
        self.maps, self.borders, self.tasks, self.done = maps, borders, tasks, done
        self.submitted, self.overlapped = submitted, overlapped
        self.own: tuple[float, float] | None = None  # the calling thread's (other work, band)


class BandedFront:
    """:func:`asnn._fast.front` over one band of rows per thread: one per worker from the top,
    and the calling thread's at the bottom.

    Each band advances its own rows of the cascades (and, again, the few rows beyond it that
    its filters read, which it drops), so the bands of a frame need nothing from each other;
    the next frame's bands need the whole of this one's. A band advances its rows in place,
    except the rows that a neighbouring band reads, which it writes into a second pair of
    arrays: the neighbour still reads them as they were. Where each row's state is, in the
    cascades or the second pair, is kept per row (:meth:`settle` brings it all back into the
    cascades). :meth:`start` hands the workers their bands, :meth:`run_own` computes the calling
    thread's, and :meth:`join` waits for the workers' and completes the column sums of
    R^theta: the first band sets them, the others' rows are added in row order, so they are
    those of one pass. A frame's pass may be started before the previous one is joined: a
    worker's band waits for the previous pass's bands on the other workers. Bands are at least
    ``2 halo + 2`` rows high; a frame too small for that has fewer bands.

    The borders follow the threads' speeds and the calling thread's other work (finishing
    frames, taking the next one): the bands are sized so that the workers would have been done
    with the latest frame a little before the calling thread needs them.
    """

    _SMOOTHING = 0.25  # weight of the latest frame in the running estimates
    _MARGIN = 50e-6  # seconds a worker should be done before its band is needed

    def __init__(self, coefficients: _fast.FrontCoefficients, workers: list[Worker]):
        self.coefficients = coefficients
        self.workers = workers
        self._min_rows = 2 * coefficients.halo + 2
        # per thread (the workers', then the calling thread's): seconds of other work per
        # frame and seconds per row of band
        self._other = [0.0] * (len(workers) + 1)
        self._cost = [0.0] * (len(workers) + 1)
        self._borders: list[int] | None = None
        self._flight: deque[_Pass] = deque()  # started, not joined yet
        self._versions = np.zeros(0, np.int8)  # where each row's state is after the passes
        self._own_end: float | None = None  # when the calling thread's latest band ended
        self._waited = 0.0  # seconds it waited in join() since

    def borders(self, height: int) -> list[int]:
        """Where the bands of a frame of this height start (the last band the calling
        thread's), and the height."""
        n = min(len(self.workers) + 1, height // self._min_rows)
        if n < 2:
            return [0, height]
        if self._borders is not None and self._borders[-1] == height \
                and len(self._borders) == n + 1:
            return self._borders
        return [round(i * height / n) for i in range(n + 1)]

    def start(self, p: np.ndarray, stages: tuple, other: tuple, maps: _fast.FrontMaps,
              overlapped: bool = False) -> _Pass:
        """Start a frame's pass: hand the workers their bands.

        ``stages`` are the cascades, ``other`` the second pair of arrays; ``overlapped`` says
        that the calling thread finishes another frame while the workers compute (for the
        borders).
        """
        h, w = p.shape
        borders = self.borders(h)
        c = self.coefficients
        if len(self._versions) != h:
            self._versions = np.zeros(h, np.int8)
        read, write = self._versions, self._versions.copy()
        for m in borders[1:-1]:  # the rows two bands read go where the other band does not
            write[m - c.halo:m + c.halo] ^= 1
        self._versions = write
        # the bands read rows that the previous pass's bands, on other workers, may still write
        # (the calling thread's band of it is done: it ran before this call)
        before = self._flight[-1].tasks if self._flight else []
        done = np.zeros(len(borders) - 2, np.int64)  # the workers' bands set theirs

        def band(i):
            for task in before:
                task.join()
            _fast.front(p, stages, c, maps, _fast.scratch(w, p.dtype),
                        (borders[i], borders[i + 1]), other, (read, write), sums=i == 0,
                        done=done[i:i + 1])

        tasks = [worker.submit(lambda i=i: band(i))
                 for i, worker in enumerate(self.workers[:len(borders) - 2])]
        flight = _Pass(p, stages, other, (read, write), maps, borders, tasks, done,
                       time.perf_counter(), overlapped)
        self._flight.append(flight)
        return flight

    def settle(self, stages: tuple, other: tuple) -> None:
        """Bring every row's state back into the cascades (no pass in flight)."""
        if self._flight:
            raise RuntimeError("join() the passes in flight first")
        there = np.flatnonzero(self._versions)
        for s, o in zip(stages, other):
            s[:, there] = o[:, there]
        self._versions[there] = 0

    def run_own(self, flight: _Pass) -> None:
        """Compute the calling thread's band of a started pass (the pass before it joined)."""
        begun = time.perf_counter()
        other = 0.0
        if flight.overlapped and self._own_end is not None:
            other = begun - self._own_end - self._waited
        borders = flight.borders
        cpu = time.thread_time()
        _fast.front(flight.p, flight.stages, self.coefficients, flight.maps,
                    _fast.scratch(flight.p.shape[1], flight.p.dtype),
                    (borders[-2], borders[-1]), flight.other, flight.versions,
                    sums=len(borders) == 2)
        flight.own = (other, time.thread_time() - cpu)
        self._own_end = time.perf_counter()
        self._waited = 0.0

    def join(self, flight: _Pass) -> None:
        """Wait for the workers' bands of a pass (raising a band's exception) and complete its
        column sums. Passes are joined in the order they were started."""
        if not self._flight or self._flight[0] is not flight:
            raise RuntimeError("passes are joined in the order they were started")
        self._flight.popleft()
        # A band's kernel sets its flag when done; only then does its thread need the GIL, to
        # return: a pass whose flags are all set is complete, whatever its threads do next.
        if not flight.done.all():
            waiting = time.perf_counter()
            for task in flight.tasks:
                task.join()  # all of them, before anything is raised
            self._waited += time.perf_counter() - waiting
            for task in flight.tasks:
                task.wait()
        borders = flight.borders
        for i in range(1, len(borders) - 1):
            _fast.add_column_sums(flight.maps, borders[i], borders[i + 1])
        if flight.tasks and flight.own is not None:
            n = len(flight.tasks)
            self._measure(borders, list(range(n)) + [len(self.workers)], [
                (0.0 if flight.overlapped else t.started - flight.submitted, t.cpu)
                for t in flight.tasks] + [flight.own])

    def abandon(self) -> None:
        """Wait for the workers' bands in flight, whatever their outcome, and forget them
        (after an error: the model's state is then that of an interrupted step)."""
        while self._flight:
            for task in self._flight.popleft().tasks:
                task.join()

    def _measure(self, borders: list[int], threads: list[int],
                 times: list[tuple[float, float | None]]) -> None:
        """Update the estimates of the threads of the bands from their (other work, band)
        seconds of one frame (band: processor time), then the borders: rows_i = (finish - other_i) / cost_i, summing
        to the height, with the workers' other work counted ``_MARGIN`` longer."""
        a = self._SMOOTHING
        cost, other = self._cost, self._other
        for i, (k, (busy, band)) in enumerate(zip(threads, times)):
            if band is None:  # a worker's band that was done before it could say how long
                continue
            c = band / (borders[i + 1] - borders[i])
            cost[k] = c if cost[k] == 0 else (1 - a) * cost[k] + a * c
            other[k] = (1 - a) * other[k] + a * max(busy, 0.0)
        if not all(cost[k] > 0 for k in threads):
            return
        n, height = len(threads), borders[-1]
        ahead = [other[k] + (self._MARGIN if k < len(self.workers) else 0.0) for k in threads]
        speed = [1.0 / cost[k] for k in threads]
        finish = (height + sum(o * v for o, v in zip(ahead, speed))) / sum(speed)
        rows = [max((finish - o) * v, self._min_rows) for o, v in zip(ahead, speed)]
        scale, end, new = height / sum(rows), 0.0, [0]
        for i in range(n - 1):  # every band at least min_rows high
            end += rows[i] * scale
            new.append(int(min(max(round(end), new[-1] + self._min_rows),
                               height - (n - 1 - i) * self._min_rows)))
        self._borders = new + [height]
