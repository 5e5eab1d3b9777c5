"""Zenoh key expressions of the service, in one place (CONTRACT.md, "Zenoh key expressions").

``<prefix>/<robot>/frame``     camera -> worker     Frame
``<prefix>/<robot>/response``  worker -> anyone     Response, one per processed frame
``<prefix>/<robot>/warning``   worker -> fleet      Response, only when ``collision`` is true
``<prefix>/<robot>/preview``   camera -> dashboards Preview, a low-rate thumbnail (optional
                                                    extension, docs/contract.md)
``<prefix>/<robot>/refused``   worker -> camera     Refusal: the worker refuses the robot's frames,
                                                    at most one a second (optional extension)

Worker coordination (docs/operations.md); the ``@worker`` chunk is *verbatim* in Zenoh (it starts
with ``@``), so ``<prefix>/*/...`` and ``<prefix>/**`` never match these keys, and no robot id
(``[A-Za-z0-9_-]``) can collide with them:

``<prefix>/@worker/<id>``         liveliness token of a running worker (ownership of robots)
``<prefix>/@worker/<id>/status``  queryable: the worker's counters and robots (msgpack map)
``<prefix>/@worker/<id>/robot/<robot>``  liveliness token: worker ``id`` serves ``robot`` (or
                                 is warm to take it over)

Cameras announce themselves (optional, docs/contract.md), so that workers subscribe to their
frames at once; ``@camera`` is verbatim too:

``<prefix>/@camera/<robot>``      liveliness token of a camera publishing ``robot``'s frames
"""

from __future__ import annotations

import re

__all__ = ["DEFAULT_PREFIX", "KINDS", "KeySchemeError", "check_prefix", "check_robot",
           "frame_key", "parse_key", "response_key", "warning_key", "frames", "responses",
           "warnings", "preview_key", "previews", "refusal_key", "refusals", "WORKER_CHUNK",
           "worker_token_key", "worker_tokens", "worker_status_key", "worker_statuses",
           "parse_worker_token", "CLAIM_CHUNK", "claim_key", "claims", "parse_claim",
           "CAMERA_CHUNK", "camera_token_key", "camera_tokens", "parse_camera_token"]

DEFAULT_PREFIX = "asnn"
KINDS = ("frame", "response", "warning", "preview", "refused")
ROBOT_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,64}")
_CHUNK = re.compile(r"[^/*$?#\s]+")


class KeySchemeError(ValueError):
    """A robot id, prefix or key that does not follow the key scheme."""


def check_robot(robot: str, what: str = "robot") -> str:
    """Return ``robot`` if it is a valid robot id (one chunk of ``[A-Za-z0-9_-]{1,64}``);
    ``what`` names the id in the error (a worker's ids take the same alphabet)."""
    if not isinstance(robot, str) or not ROBOT_PATTERN.fullmatch(robot):
        raise KeySchemeError(f"invalid {what} id {robot!r}: use 1 to 64 of A-Z a-z 0-9 _ -")
    return robot


MAX_PREFIX_LEN = 256  # characters of a prefix: every key and log line of the fleet holds it


def check_prefix(prefix: str) -> str:
    """Return ``prefix`` if it is one or more literal chunks (no wildcards, no empty chunk), at
    most :data:`MAX_PREFIX_LEN` characters."""
    if not isinstance(prefix, str) or not prefix or not all(
            _CHUNK.fullmatch(c) for c in prefix.split("/")):
        raise KeySchemeError(f"invalid key prefix {prefix!r}: literal chunks separated by '/'")
    if len(prefix) > MAX_PREFIX_LEN:
        raise KeySchemeError(f"key prefix of {len(prefix)} characters: at most {MAX_PREFIX_LEN}")
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


def refusal_key(robot: str, prefix: str = DEFAULT_PREFIX) -> str:
    """Where a worker tells a robot's camera that it refuses its frames (docs/contract.md)."""
    return _key(prefix, robot, "refused")


def refusals(prefix: str = DEFAULT_PREFIX, robot: str | None = None) -> str:
    return refusal_key(robot or "*", prefix)


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


# ---------------------------------------------------------------- workers (docs/operations.md)

WORKER_CHUNK = "@worker"


def _verbatim_key(chunk: str, ident: str, prefix: str) -> str:
    """``<prefix>/<chunk>/<id>`` for a robot-id-like ``ident`` (or ``*``)."""
    ident = ident if ident == "*" else check_robot(ident)
    return f"{check_prefix(prefix)}/{chunk}/{ident}"


def worker_token_key(worker: str, prefix: str = DEFAULT_PREFIX) -> str:
    """``<prefix>/@worker/<id>``: the liveliness token of worker ``id`` (a robot-id-like chunk)."""
    return _verbatim_key(WORKER_CHUNK, worker, prefix)


def worker_tokens(prefix: str = DEFAULT_PREFIX) -> str:
    """Liveliness subscription key for every worker under ``prefix``."""
    return worker_token_key("*", prefix)


def worker_status_key(worker: str, prefix: str = DEFAULT_PREFIX) -> str:
    """``<prefix>/@worker/<id>/status``: the status queryable of worker ``id``."""
    return worker_token_key(worker, prefix) + "/status"


def worker_statuses(prefix: str = DEFAULT_PREFIX) -> str:
    """Query key reaching the status queryable of every worker under ``prefix``."""
    return worker_status_key("*", prefix)


def parse_worker_token(key: str, prefix: str = DEFAULT_PREFIX) -> str:
    """The worker id of a ``<prefix>/@worker/<id>`` token key.

    Raises
    ------
    KeySchemeError
        If the key is not a worker token under ``prefix``.
    """
    return _id_under(key, prefix, WORKER_CHUNK)


def _id_under(key: str, prefix: str, chunk: str) -> str:
    """The id of a ``<prefix>/<chunk>/<id>`` key (a robot-id-like chunk)."""
    head = f"{check_prefix(prefix)}/{chunk}/"
    key = str(key)
    if not key.startswith(head) or "/" in key[len(head):]:
        raise KeySchemeError(f"key {key!r} is not {head}<id>")
    return check_robot(key[len(head):])


CLAIM_CHUNK = "robot"


def claim_key(worker: str, robot: str, prefix: str = DEFAULT_PREFIX) -> str:
    """``<prefix>/@worker/<id>/robot/<robot>``: worker ``id``'s claim on ``robot`` (a liveliness
    token while it serves the robot, or is warm to take it over)."""
    robot = robot if robot == "*" else check_robot(robot)
    return f"{worker_token_key(worker, prefix)}/{CLAIM_CHUNK}/{robot}"


def claims(prefix: str = DEFAULT_PREFIX) -> str:
    """Liveliness subscription key for every worker's claims under ``prefix``."""
    return claim_key("*", "*", prefix)


def parse_claim(key: str, prefix: str = DEFAULT_PREFIX) -> tuple[str, str]:
    """``(worker, robot)`` of a claim key.

    Raises
    ------
    KeySchemeError
        If the key is not a claim under ``prefix``.
    """
    head = f"{check_prefix(prefix)}/{WORKER_CHUNK}/"
    key = str(key)
    parts = key[len(head):].split("/") if key.startswith(head) else []
    if len(parts) != 3 or parts[1] != CLAIM_CHUNK:
        raise KeySchemeError(f"key {key!r} is not {head}<id>/{CLAIM_CHUNK}/<robot>")
    return check_robot(parts[0]), check_robot(parts[2])


# ---------------------------------------------------------------- cameras (docs/contract.md)

CAMERA_CHUNK = "@camera"


def camera_token_key(robot: str, prefix: str = DEFAULT_PREFIX) -> str:
    """``<prefix>/@camera/<robot>``: the liveliness token of the camera publishing ``robot``."""
    return _verbatim_key(CAMERA_CHUNK, robot, prefix)


def camera_tokens(prefix: str = DEFAULT_PREFIX) -> str:
    """Liveliness subscription key for every camera under ``prefix``."""
    return camera_token_key("*", prefix)


def parse_camera_token(key: str, prefix: str = DEFAULT_PREFIX) -> str:
    """The robot id of a ``<prefix>/@camera/<robot>`` token key.

    Raises
    ------
    KeySchemeError
        If the key is not a camera token under ``prefix``.
    """
    return _id_under(key, prefix, CAMERA_CHUNK)
