"""What every fleet viewer takes from the wire, and how: ``asnn alerts``, the dashboard and the
Foxglove server validate the fleet's samples alike.

A response or warning must name the robot of its key, a warning must say ``collision``, a
preview is at most ``service.messages.MAX_PREVIEW_BYTES`` and decodes, and a viewer keeps at
most MAX_TARGETS targets per response (docs/operations.md, "Hostile input").
"""

from __future__ import annotations

from collections.abc import Callable

from service import keys
from service.messages import (MessageError, Preview, Refusal, Response, check_preview,
                              decode_preview, decode_refusal, decode_response)

__all__ = ["MAX_TARGETS", "STALE_S", "decode_fleet_sample", "stale_robot", "take_fleet_sample"]

MAX_TARGETS = 16      # targets kept per response (the worker finds a few)
STALE_S = 3.0         # no response for this long: stale (no worker watches it)


def decode_fleet_sample(key: str, payload: bytes, prefix: str
                        ) -> tuple[str, str, Response | Preview | Refusal]:
    """Validate a sample of ``<prefix>/<robot>/(response|warning|preview|refused)``: ``(robot,
    kind, message)``, as every fleet viewer takes it.

    A preview must be at most MAX_PREVIEW_BYTES and its image is decoded
    (:func:`service.messages.check_preview`); a response or warning must name the robot of its
    key, and a warning must say ``collision``. Targets beyond MAX_TARGETS are left out (the
    worker finds a few; a viewer keeps or draws no more).

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
        message = decode_refusal(payload, robot)
    elif kind in ("response", "warning"):
        message = decode_response(payload)
        if message.robot != robot:
            raise MessageError("bad-key", f"{kind} of robot {message.robot!r} on {key}")
        if kind == "warning" and not message.collision:
            raise MessageError("invalid-field", "a warning without collision: true")
        if len(message.targets) > MAX_TARGETS:
            message = message.model_copy(update={"targets": message.targets[:MAX_TARGETS]})
    else:
        raise MessageError("bad-key", f"{key!r} is not a response, warning, preview or refusal")
    return robot, kind, message


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
