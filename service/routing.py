"""Which robots' frames a worker receives, which it answers and which it claims.

Several workers share the robots of one prefix (:mod:`service.ownership`: the rendezvous-hash
owner of a robot over the live workers serves it). Each worker subscribes to the frames of its
own robots only, ``<prefix>/<robot>/frame`` per robot, so that every frame crosses the router
once, to the worker that needs it. This module is the bookkeeping behind those subscriptions; it
imports no Zenoh (:class:`service.worker.Worker` applies its :meth:`Routes.plan`).

What the fleet knows
--------------------
* **Claims**: a worker declares the liveliness token ``<prefix>/@worker/<id>/robot/<robot>``
  while it answers a robot, or once it is warm to take it over. Every worker watches every
  claim, so all know every served robot.
* **Cameras** that announce themselves declare ``<prefix>/@camera/<robot>`` (``asnn camera``
  does): their robots are known before their first frame.
* **Discovery**: a camera that does not announce itself is found by its frames. A worker alone
  on its prefix subscribes to ``<prefix>/*/frame`` all the time (it serves every robot anyway);
  with several, one of them, the **scanner** (the rendezvous owner of :data:`SCAN_KEY`),
  subscribes to it for a short window every few seconds (:data:`service.worker.SCAN_INTERVAL`).
  A robot it finds that nobody claims, it *adopts*: it serves the robot at once and claims it,
  and the robot's owner then takes it over as below.
* A robot whose claims and announcement are gone (its worker died) is **remembered** for
  ``remember`` seconds, so that its new owner subscribes to it at once.

Roles
-----
For each known robot, with ``owner`` its rendezvous owner (among the others once this worker is
leaving) and ``others`` the other workers that claim it:

==============  =========================================================================
``serving``     owner is this worker, and nobody else claims the robot or this worker claims
                it too: subscribe, answer, claim (once a frame of it was valid)
``warming``     owner is this worker but another worker claims it and this one does not yet:
                subscribe and step its frames silently; once warm (the model has stepped
                enough frames), claim it and serve
``releasing``   this worker claims (or adopted) the robot but another owns it, and the owner
                has not claimed it yet: go on answering until it does
(none)          forget the robot: no subscription, no claim, no model state
==============  =========================================================================

So a hand-over is warm: a new owner (a worker that joins, or the heir of one that stops) warms
its model up on the robot's frames while the previous owner still answers, claims and answers
when warm, and the previous owner lets go when it sees the claim. No frame goes unanswered; a
frame that arrives in the moment between the claim and the previous owner seeing it (about a
millisecond on one router) may be answered by both (responses carry ``worker``). Only when the previous owner vanishes without a word (a crash,
a lost network: its claims vanish with its session) does the new owner start cold.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from .core import RobotView
from .ownership import Membership, owner

__all__ = ["SCAN_KEY", "Route", "Routes"]

SCAN_KEY = "@scan"  # rendezvous key of the scanning worker (no robot id contains "@")


@dataclass(frozen=True)
class Route:
    """What a worker does with one robot: its role and whether it claims the robot."""

    role: str
    claim: bool

    @property
    def answers(self) -> bool:
        return self.role in ("serving", "releasing")


class Routes:
    """One worker's view of the fleet's robots (thread-safe).

    Parameters
    ----------
    me : str
        This worker's id.
    remember : float
        Seconds a robot stays known after its last claim, announcement or frame went.
    max_known : int
        Robots known at most (claims, announcements and adoptions beyond it are ignored, so a
        flood of ids cannot grow the worker's memory); a remembered robot is forgotten to make
        room for one with live evidence.
    clock : callable
        Monotonic seconds.
    """

    def __init__(self, me: str, *, remember: float = 60.0, max_known: int = 1024,
                 clock: Callable[[], float] = time.monotonic):
        self.me = me
        self.membership = Membership(me)
        self.remember = float(remember)
        self.max_known = int(max_known)
        self.clock = clock
        self._claims: dict[str, set[str]] = {}  # robot -> the other workers claiming it
        self._cameras: set[str] = set()  # robots whose camera announces itself
        self._adopted: set[str] = set()  # found by this worker's scan, served until claimed
        self._claimed: set[str] = set()  # this worker's claims
        self._remembered: dict[str, float] = {}  # robot -> when its last evidence went
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ what the fleet says

    def claim(self, worker: str, robot: str, present: bool) -> bool:
        """Another worker's claim on a robot appeared (``present``) or went; True if it changed
        anything."""
        if worker == self.me:
            return False
        with self._lock:
            holders = self._claims.get(robot)
            if present:
                if holders is None:
                    if not self._room_locked(robot):
                        return False
                    holders = self._claims[robot] = set()
                changed = worker not in holders
                holders.add(worker)
                return changed
            if holders is None or worker not in holders:
                return False
            holders.discard(worker)
            if not holders:
                del self._claims[robot]
                self._remember_locked(robot, self.clock())
            return True

    def camera(self, robot: str, present: bool) -> bool:
        """A camera's announcement appeared or went; True if it changed anything."""
        with self._lock:
            if present:
                if robot in self._cameras or not self._room_locked(robot):
                    return False
                self._cameras.add(robot)
                return True
            if robot not in self._cameras:
                return False
            self._cameras.discard(robot)
            self._remember_locked(robot, self.clock())
            return True

    def adopt(self, robot: str) -> bool:
        """A robot this worker's scan found (a valid frame of it was taken); True if it was
        unknown and is now adopted."""
        with self._lock:
            if self._known_locked(robot) or not self._room_locked(robot):
                return False
            self._adopted.add(robot)
            return True

    # ------------------------------------------------------------------ queries

    def known(self, robot: str) -> bool:
        """Whether the robot is claimed, announced, adopted or remembered."""
        with self._lock:
            return self._known_locked(robot)

    def role(self, robot: str) -> str | None:
        """This worker's role for the robot (see the module notes), None for none."""
        with self._lock:
            return self._role_locked(robot)

    def takes(self, robot: str) -> bool:
        """Whether this worker takes the robot's frames: it has a role for it, or nobody knows
        the robot yet (its frames came through the scan, to be adopted)."""
        with self._lock:
            return not self._known_locked(robot) or self._role_locked(robot) is not None

    def answers(self, robot: str) -> bool:
        """Whether this worker answers the robot's frames (serving or releasing it)."""
        return self.role(robot) in ("serving", "releasing")

    def alone(self) -> bool:
        """No other live worker (and this one is not leaving)."""
        return not self.membership.leaving and not self.membership.others()

    def scanner(self) -> bool:
        """Whether this worker scans for robots that do not announce themselves."""
        if self.membership.leaving:
            return False
        return owner(SCAN_KEY, self.membership.live()) == self.me

    def counts(self) -> dict:
        """Robots known by kind of evidence (for the status)."""
        with self._lock:
            return {"claimed": len(self._claimed), "claimed_by_others": len(self._claims),
                    "announced": len(self._cameras), "adopted": len(self._adopted),
                    "remembered": len(self._remembered)}

    # ------------------------------------------------------------------ the plan

    def plan(self, tracked: Mapping[str, RobotView]) -> dict[str, Route]:
        """Every robot this worker has a role for, with its route.

        ``tracked`` are the robots whose frames the worker's core holds. Robots not in the
        result are to be forgotten (no subscription, no claim, no state). Records this worker's
        claims as the plan has them, drops adoptions the core gave up, and forgets what has had
        no evidence for ``remember`` seconds.
        """
        now = self.clock()
        with self._lock:
            for robot in self._adopted - tracked.keys():  # its frame failed, or it went idle
                self._adopted.discard(robot)
                self._remember_locked(robot, now)
            robots = (self._claims.keys() | self._cameras | self._adopted | self._claimed
                      | self._remembered.keys() | tracked.keys())
            routes: dict[str, Route] = {}
            claimed = set()
            for robot in robots:
                if (robot in self._claims or robot in self._cameras or robot in self._adopted
                        or robot in self._claimed or robot in tracked):
                    self._remembered.pop(robot, None)
                elif now - self._remembered.setdefault(robot, now) > self.remember:
                    del self._remembered[robot]
                    continue
                role = self._role_locked(robot)  # from the claims of the previous plan
                if role is None:
                    continue
                view = tracked.get(robot)
                claim = view is not None and (view.warm if role == "warming" else view.proven)
                if claim:
                    claimed.add(robot)
                    self._adopted.discard(robot)
                routes[robot] = Route(role, claim)
            for robot in self._claimed - claimed:  # let go: known a while longer
                if robot not in self._remembered:
                    self._remember_locked(robot, now)
            self._claimed = claimed
            return routes

    # ------------------------------------------------------------------ internals

    def _remember_locked(self, robot: str, now: float) -> None:
        """Remember a robot whose last evidence went now; at most ``max_known`` are, the
        oldest forgotten first. Each robot of the plan costs the worker a subscription (and
        the thread Zenoh runs its Python callback on): a flood of robot ids, each tracked for a
        moment, left 1,200 threads in a worker for a minute, more with every new id."""
        self._remembered.pop(robot, None)
        self._remembered[robot] = now
        while len(self._remembered) > self.max_known:
            del self._remembered[next(iter(self._remembered))]

    def _known_locked(self, robot: str) -> bool:
        return (robot in self._claims or robot in self._cameras or robot in self._adopted
                or robot in self._claimed or robot in self._remembered)

    def _room_locked(self, robot: str) -> bool:
        """Whether one more robot may be known. When the table is full, the robot remembered
        longest is forgotten to make room: a robot with live evidence (a camera announcing it,
        a claim) outranks one whose evidence went, which after a flood of ids would otherwise
        keep real robots out for ``remember`` seconds."""
        if self._known_locked(robot):
            return True
        live = self._claims.keys() | self._cameras | self._adopted | self._claimed
        if len(live | self._remembered.keys()) < self.max_known:
            return True
        while self._remembered:
            oldest = next(iter(self._remembered))
            del self._remembered[oldest]
            if oldest not in live:  # else it was known twice (until the next plan): go on
                return True
        return False

    def _role_locked(self, robot: str) -> str | None:
        me = self.me
        owner_now = self.membership.owner(robot)
        others = self._claims.get(robot, ())
        if owner_now == me:
            return "warming" if others and robot not in self._claimed else "serving"
        if (robot in self._claimed or robot in self._adopted) and owner_now not in others:
            return "releasing"
        return None
