"""Zenoh key expressions of the service, in one place (CONTRACT.md, "Zenoh key expressions").

``<prefix>/<robot>/frame``     camera -> worker     Frame
``<prefix>/<robot>/response``  worker -> anyone     Response, one per processed frame
``<prefix>/<robot>/warning``   worker -> fleet      Response, only when ``collision`` is true
``<prefix>/<robot>/preview``   camera -> dashboards Preview, a low-rate thumbnail (optional
                                                    extension, docs/contract.md)
"""

from __future__ import annotations

import re

__all__ = ["DEFAULT_PREFIX", "KINDS", "KeySchemeError", "check_prefix", "check_robot", "frame_key",
           "parse_key", "response_key", "warning_key", "frames", "responses", "warnings",
           "preview_key", "previews"]

DEFAULT_PREFIX = "asnn"
KINDS = ("frame", "response", "warning", "preview")
ROBOT_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,64}")
_CHUNK = re.compile(r"[^/*$?#\s]+")


class KeySchemeError(ValueError):
    """A robot id, prefix or key that does not follow the key scheme."""


def check_robot(robot: str) -> str:
    """Return ``robot`` if it is a valid robot id (one chunk of ``[A-Za-z0-9_-]{1,64}``)."""
    if not isinstance(robot, str) or not ROBOT_PATTERN.fullmatch(robot):
        raise KeySchemeError(f"invalid robot id {robot!r}: use 1 to 64 of A-Z a-z 0-9 _ -")
    return robot


def check_prefix(prefix: str) -> str:
    """Return ``prefix`` if it is one or more literal chunks (no wildcards, no empty chunk)."""
    if not isinstance(prefix, str) or not prefix or not all(
            _CHUNK.fullmatch(c) for c in prefix.split("/")):
        raise KeySchemeError(f"invalid key prefix {prefix!r}: literal chunks separated by '/'")
    return prefix


def _key(prefix: str, robot: str, kind: str) -> str:
    return f"{check_prefix(prefix)}/{robot if robot == '*' else check_robot(robot)}/{kind}"


def frame_key(robot: str, prefix: str = DEFAULT_PREFIX) -> str:
    return _key(prefix, robot, "frame")


def response_key(robot: str, prefix: str = DEFAULT_PREFIX) -> str:
    return _key(prefix, robot, "response")


def warning_key(robot: str, prefix: str = DEFAULT_PREFIX) -> str:
    return _key(prefix, robot, "warning")


def frames(prefix: str = DEFAULT_PREFIX, robot: str | None = None) -> str:
    """Subscription key for the frames of one robot or (``robot=None``) of all."""
    return frame_key(robot or "*", prefix)


def responses(prefix: str = DEFAULT_PREFIX, robot: str | None = None) -> str:
    return response_key(robot or "*", prefix)


def warnings(prefix: str = DEFAULT_PREFIX, robot: str | None = None) -> str:
    return warning_key(robot or "*", prefix)


def preview_key(robot: str, prefix: str = DEFAULT_PREFIX) -> str:
    return _key(prefix, robot, "preview")


def previews(prefix: str = DEFAULT_PREFIX, robot: str | None = None) -> str:
    return preview_key(robot or "*", prefix)


def parse_key(key: str, prefix: str = DEFAULT_PREFIX) -> tuple[str, str]:
    """Split ``<prefix>/<robot>/<kind>`` into ``(robot, kind)``.

    Raises
    ------
    KeySchemeError
        If the key is not under ``prefix``, the robot id is invalid or the kind unknown.
    """
    key = str(key)
    head = check_prefix(prefix) + "/"
    if not key.startswith(head):
        raise KeySchemeError(f"key {key!r} is not under prefix {prefix!r}")
    parts = key[len(head):].split("/")
    if len(parts) != 2 or parts[1] not in KINDS:
        raise KeySchemeError(f"key {key!r} is not <prefix>/<robot>/<{'|'.join(KINDS)}>")
    return check_robot(parts[0]), parts[1]
