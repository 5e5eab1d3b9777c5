"""What every fleet viewer takes from the wire, and how: ``asnn alerts``, the dashboard and the
Foxglove server validate the fleet's samples alike.

A response or warning must name the robot of its key, a warning must say ``collision``, a
preview is at most ``service.messages.MAX_PREVIEW_BYTES`` and decodes, and a viewer keeps at
most MAX_TARGETS targets per response (docs/operations.md, "Hostile input").
"""

from __future__ import annotations

import hashlib
import logging
import threading
import time
import unicodedata
from collections import OrderedDict
from collections.abc import Callable

from service import keys
from service.logutil import RateLimitedLog
from service.messages import (MAX_NOTE_LEN, MessageError, Preview, Refusal, Response,
                              check_preview, decode_preview, decode_refusal, decode_response)
from service.streams import CONTESTED_FOR_S

__all__ = ["ANSWERED_FRAMES", "MAX_TARGETS", "PREVIEW_STAMP_SLACK_S", "RECENT_SAMPLES", "STALE_S",
           "FleetSubscriber", "RecentSamples", "answered_frame", "decode_fleet_sample",
           "declare_warning_subscribers", "foreign_preview", "refusal_shown", "remember_answer", "stale_robot",
           "take_fleet_sample"]

log = logging.getLogger("asnn.fleet")

MAX_TARGETS = 16      # targets kept per response (the worker finds a few)
STALE_S = 3.0         # no response for this long: stale (no worker watches it)
RECENT_SAMPLES = 4096  # warnings remembered to drop the second copy of each (two subscribers)
ANSWERED_FRAMES = 32  # (seq, stamp) of a robot's latest answered frames, for answered_frame
PREVIEW_STAMP_SLACK_S = 0.001  # a preview's stamp against its frame's answers (a camera's rounding)
# previews waiting to be checked (each is decoded, up to 1 Mpx: 20 ms for a 5 kB png that
# declares one): a ring that drops the oldest, drained by a thread of its own
PREVIEW_RING = 64


def decode_fleet_sample(key: str, payload: bytes, prefix: str
                        ) -> tuple[str, str, Response | Preview | Refusal]:
    """Validate a sample of ``<prefix>/<robot>/(response|warning|preview|refused)``: ``(robot,
    kind, message)``, as every fleet viewer takes it.

    A preview must be at most MAX_PREVIEW_BYTES and its image is decoded
    (:func:`service.messages.check_preview`); a response or warning must name the robot of its
    key, and a warning must say ``collision``. Targets beyond MAX_TARGETS are left out (the
    worker finds a few; a viewer keeps or draws no more), and so are the characters of
    ``model``, ``preset`` and ``worker`` (and a refusal's ``worker`` and ``detail``) beyond
    MAX_NOTE_LEN (CONTRACT.md bounds none of them), and their control and format characters.

    Raises
    ------
    MessageError
        With ``reason`` ``bad-key`` for a key outside the scheme, else the message's reason.
    """
    try:
        robot, kind = keys.parse_key(str(key), prefix)
    except keys.KeySchemeError as exc:
        raise MessageError("bad-key", str(exc)) from None
    if kind == "preview":
        message = decode_preview(payload)
        check_preview(message)  # the viewers only ever get images of the announced size
    elif kind == "refused":
        message = _with_notes(decode_refusal(payload, robot), ("worker", "detail"))
    elif kind in ("response", "warning"):
        message = decode_response(payload)
        if message.robot != robot:
            raise MessageError("bad-key", f"{kind} of robot {message.robot!r} on {key}")
        if kind == "warning" and not message.collision:
            raise MessageError("invalid-field", "a warning without collision: true")
        if len(message.targets) > MAX_TARGETS:
            message = message.model_copy(update={"targets": message.targets[:MAX_TARGETS]})
        message = _with_notes(message, ("model", "preset", "worker"))
    else:
        raise MessageError("bad-key", f"{key!r} is not a response, warning, preview or refusal")
    return robot, kind, message


def _note(text: str) -> str:
    """A name or note from the wire as the viewers show it: without control and format
    characters (a terminal's escape sequences, a right-to-left override that reverses what
    follows on a tile) and at most MAX_NOTE_LEN characters."""
    if text.isprintable() and len(text) <= MAX_NOTE_LEN:
        return text
    return "".join(c for c in text if unicodedata.category(c) not in ("Cc", "Cf"))[:MAX_NOTE_LEN]


def _with_notes(message, names: tuple[str, ...]):
    """``message`` with the string fields ``names`` as :func:`_note` shows them (CONTRACT.md
    bounds none of them: shortened and cleaned, never refused)."""
    changed = {name: _note(getattr(message, name)) for name in names}
    changed = {name: v for name, v in changed.items() if v != getattr(message, name)}
    return message.model_copy(update=changed) if changed else message


def take_fleet_sample(key: str, payload: bytes, prefix: str,
                      reject: Callable[[str, str, str], None]
                      ) -> tuple[str, str, Response | Preview | Refusal] | None:
    """:func:`decode_fleet_sample` for receivers that never raise: an invalid sample goes to
    ``reject(reason, detail, key)`` (which counts it and logs it rate-limited) and gives None."""
    try:
        return decode_fleet_sample(key, payload, prefix)
    except MessageError as exc:
        reject(exc.reason, exc.detail, key)
    except Exception as exc:  # a bug here must not take the subscriber down
        reject("internal", repr(exc), key)
    return None


def stale_robot(robots: dict, now: float, stale_after: float) -> str | None:
    """The robot of ``robots`` (name -> state with a ``touched`` time) silent longest, if it
    has been silent for more than ``stale_after`` seconds: when a viewer's table of robots is
    full, it makes room for a new one, so that a burst of ids cannot hide new robots for long.
    """
    name, quiet = min(robots.items(), key=lambda item: item[1].touched)
    return name if now - quiet.touched > stale_after else None


def answered_frame(shown, seq: int, stamp: float) -> bool:
    """Whether a preview of frame ``(seq, stamp)`` can be of the frames a robot's responses
    answer, ``shown`` (the ``(seq, stamp)`` of its latest answered frames, at most
    ANSWERED_FRAMES): its stamp lies between those of the answered frames around its ``seq``
    (PREVIEW_STAMP_SLACK_S either way; frames the worker skipped have none of their own). Two
    cameras on one key differ there: a second one's frames are refused by the worker, its
    previews are not, and shown with the robot's targets they put one camera's picture under
    the other's answers (docs/operations.md, "Two publishers on one key"). The callers ask only
    while the robot is answered (not stale): otherwise its camera alone is heard."""
    before = max(((q, t) for q, t in shown if q <= seq), default=None)
    after = min(((q, t) for q, t in shown if q >= seq), default=None)
    if not ((before is None or before[1] <= stamp + PREVIEW_STAMP_SLACK_S)
            and (after is None or after[1] >= stamp - PREVIEW_STAMP_SLACK_S)):
        return False
    if after is None and before is not None and seq > before[0]:
        # ahead of every answer (a preview sent before its frame is answered): as far ahead in
        # seq as its stamp says at the answered frames' period, not a second camera's own
        # count (seq 5000 a moment after the robot's 100 had no bound above)
        # the mean period over the answered frames (a camera read two frames at a time has
        # pairs 4 and 63 ms apart: the median of single steps read either), and a frame's
        # period of slack either way (its own step may be any of those)
        answered = sorted(shown)
        first, last = answered[0], answered[-1]
        if last[0] > first[0] and last[1] > first[1]:
            period = (last[1] - first[1]) / (last[0] - first[0])
            expected = (seq - before[0]) * period
            return (expected / 2 - period - PREVIEW_STAMP_SLACK_S <= stamp - before[1]
                    <= 2 * expected + period + PREVIEW_STAMP_SLACK_S)
    return True


def foreign_preview(preview: Preview, shown, answered: float | None, now: float,
                    stale_after: float) -> bool:
    """Whether a robot's preview is another camera's: while its responses come (the latest,
    ``answered``, at most ``stale_after`` seconds before ``now``), one that cannot be of the
    frames they answer (:func:`answered_frame`); else none is (its camera alone is heard)."""
    if answered is None or now - answered > stale_after:
        return False
    return not answered_frame(shown, preview.seq, preview.stamp)


def refusal_shown(reason: str, refused_at: float, answered: float | None, now: float) -> bool:
    """Whether a worker's refusal of a robot's frames (its latest notice of ``reason``, come at
    ``refused_at``) is still shown: until a response comes after it (``answered``, the
    latest's arrival), but a second publisher's for ``service.streams.CONTESTED_FOR_S`` after
    the latest notice whatever came (the robot's own frames are answered while the other
    camera's are refused: the worker's ``contested``). Times on one clock, seconds."""
    if reason == "second-publisher" and now - refused_at <= CONTESTED_FOR_S:
        return True
    return answered is None or answered < refused_at


def remember_answer(shown, seq: int, stamp: float) -> None:
    """Add an answered frame's ``(seq, stamp)`` to ``shown`` (a deque of ANSWERED_FRAMES), for
    :func:`answered_frame`, first dropping the answers it contradicts: those of greater
    ``seq`` and earlier ``stamp``, a stream its camera left (a restart: seq back to 0, its
    clock going on), which would keep the restarted camera's previews out until they left."""
    for entry in [(q, t) for q, t in shown if q > seq and t < stamp]:
        shown.remove(entry)
    shown.append((seq, stamp))


class RecentSamples:
    """The latest ``size`` samples seen, by a digest of their key and payload (thread safe)."""

    def __init__(self, size: int = RECENT_SAMPLES):
        self.size = size
        self._seen: OrderedDict[bytes, None] = OrderedDict()
        self._lock = threading.Lock()

    def first(self, key: str, payload: bytes) -> bool:
        """Whether this key and payload are new (not among the latest ``size`` seen)."""
        digest = hashlib.blake2b(key.encode() + b"\0" + payload, digest_size=16).digest()
        with self._lock:
            if digest in self._seen:
                self._seen.move_to_end(digest)
                return False
            self._seen[digest] = None
            if len(self._seen) > self.size:
                self._seen.popitem(last=False)
            return True


def declare_warning_subscribers(session, key: str, callback: Callable,
                                on_miss: Callable[[int, str], None] | None = None) -> list:
    """The subscribers a fleet viewer takes warnings on ``key`` with: ``callback(sample)`` once
    per warning, and ``on_miss(count, publisher)`` (``publisher``: its Zenoh id and entity id,
    ``zid/eid``) where a publisher's warnings were missed and could not be recovered (the link
    to the router cut for longer than its lease).

    An advanced subscriber asks the workers' caches for history (a late joiner gets each
    robot's latest warning, docs/contract.md) and recovers missed warnings; it orders a
    publisher's samples by the sequence numbers they carry, which anyone on an open router can
    forge: one warning copied with the worker's source id and sequence number 2^32 - 1 stopped
    every later warning of that robot from reaching ``asnn alerts`` and the dashboard. So a
    plain subscriber takes the same warnings too, and the second copy of each (the same key and
    payload, :class:`RecentSamples`) is dropped.
    """
    from zenoh.ext import HistoryConfig, RecoveryConfig, declare_advanced_subscriber

    recent = RecentSamples()

    def once(sample) -> None:
        if recent.first(str(sample.key_expr), sample.payload.to_bytes()):
            callback(sample)

    subscribers = [session.declare_subscriber(key, once)]
    try:
        subscribers.append(declare_advanced_subscriber(
            session, key, once,
            history=HistoryConfig(detect_late_publishers=True, max_samples=1),
            recovery=RecoveryConfig(periodic_queries=None, heartbeat=True)))
        if on_miss is not None:
            subscribers.append(subscribers[1].sample_miss_listener(
                lambda miss: on_miss(miss.nb, f"{miss.source.zid}/{miss.source.eid}")))
    except Exception:
        for subscriber in reversed(subscribers):
            subscriber.undeclare()
        raise
    return subscribers


class FleetSubscriber:
    """Declares the fleet viewers' subscribers on ``session`` (responses, previews, warnings,
    and with ``refusals`` the workers' refusal notices), feeding ``store`` (a
    :class:`clients.dashboard.store.FleetStore`, or anything with a ``prefix`` and an
    ``offer(key, payload)`` that never raises, such as the Foxglove bridge of
    :mod:`clients.foxglove`).

    The previews reach ``store`` from a thread of their own, through a ring of the latest
    :data:`PREVIEW_RING` (older ones are dropped: thumbnails, best effort): checking one
    decodes it, and a callback that takes that long held up the session's other
    subscribers, so that a flood of small previews that declare a megapixel delayed every
    robot's responses and warnings by 20-30 s (a control-room trial).

    A ``store`` whose ``offer`` raises (a bug) has its traceback logged at most once every
    ``log_interval`` seconds (``clock``'s), each line saying how many failed since the one
    before; the subscriber keeps feeding it."""

    def __init__(self, session, store, *, refusals: bool = False, log_interval: float = 10.0,
                 clock: Callable[[], float] = time.monotonic):
        prefix = store.prefix
        self.store = store
        self._log = RateLimitedLog(log, log_interval, clock)
        self.keys = [keys.responses(prefix), keys.warnings(prefix), keys.previews(prefix)]
        if refusals:
            self.keys.append(keys.refusals(prefix))
        import zenoh

        previews = session.declare_subscriber(keys.previews(prefix),
                                              zenoh.handlers.RingChannel(PREVIEW_RING))
        self._subscribers = [previews]
        try:
            self._subscribers += [
                *(session.declare_subscriber(key, self._on_sample) for key in self.keys
                  if key not in (keys.warnings(prefix), keys.previews(prefix))),
                # an advanced subscriber (history, recovery) and a plain one, each warning once
                *declare_warning_subscribers(session, keys.warnings(prefix), self._on_sample),
            ]
        except Exception:
            self.close()
            raise
        self._previews = threading.Thread(target=self._drain, args=(previews,),
                                          name="fleet-previews", daemon=True)
        self._previews.start()

    def _drain(self, previews) -> None:
        """The previews' thread: until their subscriber is undeclared."""
        try:
            for sample in previews:
                self._on_sample(sample)
        except Exception:  # the ring closed under us (the session closing)
            log.debug("preview subscriber ended", exc_info=True)

    def _on_sample(self, sample) -> None:
        try:
            self.store.offer(str(sample.key_expr), sample.payload.to_bytes())
        except Exception:  # offer never raises for bad input; this is a bug, keep listening
            # rate-limited: a store that fails on every sample logged a traceback per sample
            self._log.exception("offer-failed", "unexpected error on %s", sample.key_expr)

    def __enter__(self) -> FleetSubscriber:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        for subscriber in self._subscribers:
            try:
                subscriber.undeclare()
            except Exception:  # the session may already be closed
                pass
        self._subscribers = []
        thread = getattr(self, "_previews", None)
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=2.0)
