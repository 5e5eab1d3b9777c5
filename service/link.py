"""Whether a session reaches its router, said in the log.

Zenoh reconnects by itself (:mod:`service.config`'s ``connect/retry``) and says nothing meanwhile:
a camera publishing into a lost link, or a worker or a dashboard hearing nothing, would look as
if all were quiet. :class:`RouterWatch` logs a WARNING when a session that had a router has none
left, and an INFO line when one is back. A session that never had a router and has no peer is
diagnosed as a lost one is, so that a mistyped ``--connect`` of a peer, which Zenoh retries
silently, is said (again each time it is left without peers); one linked to peers only (peers
on a LAN) is not reported. It also says, at start and once a day, which of the session's
certificates expire soon (:func:`service.diagnosis.expiring_certificates`): the router checks
them at the handshake only, so one that expires while the process runs locks it out at its next
connection.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

__all__ = ["CERTIFICATES_EVERY", "CertificateCheck", "RouterWatch", "WATCH_INTERVAL"]

log = logging.getLogger("asnn.link")

WATCH_INTERVAL = 1.0  # seconds between looks at the session's routers
DIAGNOSE_AFTER = 10.0  # seconds without a router before asking why, and between two askings
CERTIFICATES_EVERY = 24 * 3600.0  # seconds between two looks at the certificates' validity


class CertificateCheck:
    """Asks ``check`` (:func:`service.diagnosis.expiring_certificates` of a configuration) at
    its first :meth:`tick` and then once every ``every`` seconds, and logs a non-empty answer
    at WARNING as ``<name>: <answer>`` on ``logger``; a check that fails says so at debug level
    only, and its caller goes on. What the router's loop and :class:`RouterWatch` share."""

    def __init__(self, name: str, check: Callable[[], str | None],
                 every: float = CERTIFICATES_EVERY, logger: logging.Logger = log):
        self.name, self.check, self.every, self.logger = name, check, every, logger
        self._at: float | None = None  # when the certificates were last looked at

    def tick(self) -> None:
        now = time.monotonic()
        if self._at is not None and now - self._at < self.every:
            return
        self._at = now
        try:
            expiring = self.check()
        except Exception:  # a check that fails says nothing; the caller goes on
            self.logger.debug("%s: certificate check failed", self.name, exc_info=True)
            return
        if expiring:
            self.logger.warning("%s: %s", self.name, expiring)


class RouterWatch:
    """Polls ``session.info.routers_zid()`` every ``interval`` seconds on a daemon thread, until
    :meth:`close` or the session closes.

    Parameters
    ----------
    session : zenoh.Session
    name : str
        What the log lines call the process (``camera r1``, ``worker w1``, ``dashboard``).
    interval : float
        Seconds between two looks.
    on_change : callable, optional
        Called with True when a router is reached (first or again) and False when it is lost,
        on the watch's thread: what a process shows its users besides the log (the
        dashboard's page).
    diagnose : callable, optional
        Returns why the router cannot be reached, or None (:func:`service.diagnosis.
        connect_failure`): asked every ``diagnose_after`` seconds while a lost router stays
        lost, or while a session that never had one reaches no peer either, its answer logged
        when it changes. Zenoh retries silently, and a router back
        with another CA, certificate or password would otherwise be a "lost its router" line
        for ever, where a fresh start says why.
    diagnose_after : float
        Seconds without a router before asking, and between two askings.
    certificates : callable, optional
        Returns which of the session's certificates expire soon, or None
        (:func:`service.diagnosis.expiring_certificates`): asked at start and every
        ``certificates_every`` seconds, its answer logged at WARNING.
    certificates_every : float
        Seconds between two askings.
    give_up_after : float, optional
        Seconds cut off (no router, and no peer; counted from the start for a session that
        never had one) after which the watch logs an ERROR, sets :attr:`gave_up` and calls
        ``on_give_up`` (the command's ``--exit-without-router``: a process its supervisor
        starts again reads its credentials again); None: never.
    on_give_up : callable, optional
        Called once, on the watch's thread, when ``give_up_after`` has passed.
    """

    def __init__(self, session, name: str, interval: float = WATCH_INTERVAL,
                 on_change: Callable[[bool], None] | None = None,
                 diagnose: Callable[[], str | None] | None = None,
                 diagnose_after: float = DIAGNOSE_AFTER,
                 certificates: Callable[[], str | None] | None = None,
                 certificates_every: float = CERTIFICATES_EVERY,
                 give_up_after: float | None = None,
                 on_give_up: Callable[[], None] | None = None):
        self.session, self.name, self.interval = session, name, interval
        self.on_change = on_change
        self.diagnose, self.diagnose_after = diagnose, diagnose_after
        self._certificates = (None if certificates is None else
                              CertificateCheck(name, certificates, certificates_every))
        # when the lost router was last diagnosed (or lost, or the watch started)
        self._asked_at = time.monotonic()
        self._asking: list | None = None  # the diagnosis under way: [thread, its answer]
        self._heard: str | None = None  # the latest answer, logged once it comes twice
        self._said: str | None = None  # the latest reason logged
        self.connected: bool | None = None  # None until a router was seen
        self.give_up_after, self.on_give_up = give_up_after, on_give_up
        self.gave_up = False  # whether give_up_after has passed cut off
        # since when the session has had no router and no peer (None: linked); from the start
        self._cut_since: float | None = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="router-watch", daemon=True)
        self._thread.start()

    def _routers(self) -> list[str]:
        return [str(zid) for zid in self.session.info.routers_zid()]

    def _unlinked(self) -> bool:
        """Whether the session is to be diagnosed: it lost its router, or never had one and has
        no peer (as cut off as one that lost its router)."""
        return self.connected is False or not self._peers()

    def _peers(self) -> bool:
        """Whether the session has a peer (True where it cannot tell: closing under us)."""
        try:
            return bool(list(self.session.info.peers_zid()))
        except Exception:  # the session closing under us: nothing left to diagnose
            return True

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                if self.session.is_closed():
                    return
                routers = self._routers()
            except Exception as exc:  # the session closing under us, or not a Zenoh session
                log.debug("%s: router watch ended: %r", self.name, exc)
                return
            if routers:
                self._cut_since = None
            if routers and self.connected is not True:
                if self.connected is False:
                    log.info("%s: reached the router again (%s)", self.name, ", ".join(routers))
                self._changed(True)
                self._asking = None  # an answer still to come is about a router found since
            elif not routers and self.connected:
                log.warning("%s: lost its router; Zenoh retries the connection (nothing is "
                            "sent or received meanwhile)", self.name)
                self._changed(False)
                self._asked_at, self._heard, self._said = time.monotonic(), None, None
                self._cut_since = time.monotonic()
            elif not routers:
                if self._unlinked():
                    if self._cut_since is None:
                        self._cut_since = time.monotonic()
                    if self.diagnose is not None:
                        self._why()
                else:  # linked to peers: a time without any, later, is a new outage, its
                    # reason said anew and counted from then, as a lost router's is
                    self._asked_at, self._heard, self._said = time.monotonic(), None, None
                    self._asking, self._cut_since = None, None
            self._give_up_when_due()
            if self._certificates is not None:
                self._certificates.tick()
            self._stop.wait(self.interval)

    def _give_up_when_due(self) -> None:
        """Once the session has been cut off (no router, and no peer) for ``give_up_after``
        seconds: log it, set :attr:`gave_up` and call ``on_give_up``, once. A peer linked
        after the router's loss counts the time again from when it goes."""
        if self.give_up_after is None or self.gave_up or self._cut_since is None:
            return
        if self._peers():
            self._cut_since = None
            return
        if time.monotonic() - self._cut_since < self.give_up_after:
            return
        self.gave_up = True
        log.error("%s: no router reached for %g s: exiting, for its supervisor to start it "
                  "again (--exit-without-router)", self.name, self.give_up_after)
        if self.on_give_up is not None:
            try:
                self.on_give_up()
            except Exception:  # the watch outlives a listener's bug, which is logged
                log.exception("%s: router watch listener failed", self.name)

    def _why(self) -> None:
        """Ask why the router stays lost, on a thread of its own (a check can take seconds a
        TLS endpoint, or hang on DNS: the watch goes on looking meanwhile), and log the answer
        once two asks in a row agree (a router just back, not yet reconnected to, reads
        refused for a moment)."""
        if self._asking is None:
            if time.monotonic() - self._asked_at >= self.diagnose_after:
                asking = self._asking = [None, None]
                asking[0] = threading.Thread(target=self._ask, args=(asking,),
                                             name="router-diagnosis", daemon=True)
                asking[0].start()
            return
        if self._asking[0].is_alive():
            return
        why, self._asking = self._asking[1], None
        self._asked_at = time.monotonic()  # after it: a check may take a few seconds
        if why and why == self._heard and why != self._said:
            # a session that never had a router may be a peer whose endpoint is another peer
            log.warning("%s: %s: %s", self.name, "still no router" if self.connected is False
                        else "reaches no router or peer", why)
            self._said = why
        self._heard = why

    def _ask(self, asking: list) -> None:
        try:
            asking[1] = self.diagnose()
        except Exception:  # a diagnosis that fails says nothing; the watch goes on
            log.debug("%s: router diagnosis failed", self.name, exc_info=True)

    def _changed(self, connected: bool) -> None:
        self.connected = connected
        if self.on_change is not None:
            try:
                self.on_change(connected)
            except Exception:  # the watch outlives a listener's bug, which is logged
                log.exception("%s: router watch listener failed", self.name)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2 * self.interval + 1.0)

    def __enter__(self) -> RouterWatch:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
