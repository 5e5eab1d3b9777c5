"""Evaluation work spread over processes, stopped at once by Ctrl-C.

``concurrent.futures.ProcessPoolExecutor`` leaves a ``with`` block only when every task it was
given has run, so an interrupted evaluation used to finish its whole queue before it exited.
:func:`run_tasks` cancels what has not started and ends the workers at once instead, and the
workers ignore SIGINT themselves (a terminal sends it to the whole process group): the parent
alone decides, and no worker prints a traceback of its own.
"""

from __future__ import annotations

import signal
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

__all__ = ["run_tasks"]


def run_tasks(function: Callable, tasks: Sequence[tuple], jobs: int
              ) -> Iterator[tuple[int, object]]:
    """``(index, function(*tasks[index]))`` for every task, as each finishes.

    With ``jobs`` <= 1 the tasks run here, in order; otherwise in ``jobs`` processes (the
    function and its arguments must pickle). An exception in a task is raised here; when the
    caller stops early (an exception, Ctrl-C, or a generator left unfinished) the tasks not yet
    started are cancelled and the workers are ended without waiting for the running ones.
    """
    jobs = min(jobs, len(tasks))  # a pool starts all its processes at once
    if jobs <= 1:
        for index, task in enumerate(tasks):
            yield index, function(*task)
        return
    pool = ProcessPoolExecutor(max_workers=jobs, initializer=_worker_signals)
    finished = False
    try:
        pending = {pool.submit(function, *task): index for index, task in enumerate(tasks)}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                yield pending.pop(future), future.result()
        finished = True
    finally:
        if finished:
            pool.shutdown()
        else:
            _stop(pool)


def _worker_signals() -> None:
    """A worker ignores SIGINT and dies of SIGTERM, whatever handlers its parent had (a forked
    worker inherits them: one that set an event on SIGTERM made ``terminate`` do nothing)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _stop(pool: ProcessPoolExecutor) -> None:
    """Cancel the queued tasks and end the workers now (the running tasks' results are lost:
    the caller is leaving). The executor keeps its processes and its manager thread in private
    attributes; where a Python version has none, the workers finish their current task and exit."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            # SIGKILL: a worker forked a moment ago may not have reset the SIGTERM handler it
            # inherited yet (_worker_signals), and a kept handler made terminate() do nothing
            process.kill()
    # The manager thread joins the workers itself once it sees them die. Two threads reaping
    # one child race: the loser's waitpid fails, and multiprocessing then reports the dead
    # worker as still running until the winner records its exit code. So the manager reaps
    # first, and the joins below only confirm. SIGKILL cannot be refused, but a busy machine
    # may take seconds to tear a forked copy of a large process down (a full test run under
    # load once took longer than 5 s).
    if manager is not None:
        manager.join(timeout=60)
    for process in processes:
        process.join(timeout=60)
