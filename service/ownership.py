"""Which worker serves which robot: rendezvous hashing over the live worker set.

Every worker declares a liveliness token ``<prefix>/@worker/<id>`` and watches the others'.
Each worker computes, for every robot, the owner among the live workers: the worker ``w`` with the
highest score ``hash(w, robot)`` (rendezvous or highest-random-weight hashing). All workers with
the same view of the live set agree on the owner without talking to each other, a robot moves
only when its owner leaves or when a newcomer outscores it, and a newcomer takes about 1/n of the
robots. A worker takes only the frames of the robots it owns.

Views differ only while a membership change propagates (milliseconds on one router): a worker
that joins reads the live set before it takes any frame, a worker that leaves cleanly withdraws
its token first, and one that dies is removed by the router when its session closes or its lease
expires (docs/operations.md).
"""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Iterable

__all__ = ["Membership", "owner", "score"]


def score(worker: str, robot: str) -> int:
    """The rendezvous weight of ``worker`` for ``robot``: 64 bits of BLAKE2b, the same in every
    process (Python's ``hash`` is salted per process)."""
    digest = hashlib.blake2b(f"{worker}\x00{robot}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big")


def owner(robot: str, workers: Iterable[str]) -> str | None:
    """The worker of ``workers`` that serves ``robot`` (None when there is none)."""
    best = None
    for worker in workers:
        key = (score(worker, robot), worker)
        if best is None or key > best:
            best = key
    return None if best is None else best[1]


class Membership:
    """The live worker set as one worker sees it, with a cached owner per robot.

    ``me`` is always a member while the worker runs; once it is :meth:`leaving`, the owners are
    those of the others (it hands its robots over). Thread-safe.
    """

    def __init__(self, me: str, others: Iterable[str] = ()):
        self.me = me
        self._live = {me, *others}
        self._leaving = False
        self._owners: dict[str, str] = {}
        self._lock = threading.Lock()

    def live(self) -> list[str]:
        with self._lock:
            return sorted(self._live)

    def owner(self, robot: str) -> str | None:
        with self._lock:
            found = self._owners.get(robot)
            if found is None:
                found = owner(robot, self._live - {self.me} if self._leaving else self._live)
                if found is not None:
                    if len(self._owners) > 65536:  # robots come and go: keep the cache bounded
                        self._owners.clear()
                    self._owners[robot] = found
            return found

    def owns(self, robot: str) -> bool:
        return self.owner(robot) == self.me

    def others(self) -> list[str]:
        """The live workers other than ``me``."""
        with self._lock:
            return sorted(self._live - {self.me})

    def leave(self) -> None:
        """From now on ``me`` owns nothing: every robot's owner is among the others."""
        with self._lock:
            self._leaving = True
            self._owners.clear()

    @property
    def leaving(self) -> bool:
        return self._leaving

    def add(self, worker: str) -> bool:
        """A worker appeared; True if the set changed."""
        with self._lock:
            if worker in self._live:
                return False
            self._live.add(worker)
            self._owners.clear()
            return True

    def remove(self, worker: str) -> bool:
        """A worker disappeared (``me`` stays); True if the set changed."""
        with self._lock:
            if worker == self.me or worker not in self._live:
                return False
            self._live.discard(worker)
            self._owners.clear()
            return True
