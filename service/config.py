"""The Zenoh configuration of every service part, built in one place.

Precedence: Zenoh's defaults < asnn's defaults below < ``--config FILE`` (a Zenoh JSON5 config)
< the command-line options (``--mode``, ``--connect``, ``--listen``, scouting switches).
Timestamping is always enabled, because the worker's warning publisher keeps a cache for late
subscribers and Zenoh requires timestamps for that.

asnn's defaults, applied only where the config file says nothing (docs/operations.md):

* ``connect/retry``: a lost connection (a restarted router) is retried after 0.25 s, backing off
  to every 2 s (Zenoh's own: 1 s to 4 s), so cameras, workers and subscribers reconnect by
  themselves and re-declare their subscribers, publishers and liveliness tokens.

* ``transport/shared_memory/enabled``: false, unless the config file has a ``shared_memory`` key.
  Zenoh 1.10.2 enables its shared-memory transport by default; every client session on the same
  host that publishes frames through it leaves a 16 MiB pool mapped in the router and in the
  worker when it closes, never given back (about 19 MB of RSS per camera session: a camera that
  reconnects often grew them by hundreds of MB; docs/operations.md). Over TCP on one host the
  frames cost a copy more, which the worker's budget does not notice.

The lease that decides how fast a dead worker's robots move (``transport/link/tx/lease``) is
left to the config files: deploy/zenoh/*.json5 set 1 s with 4 keep-alives per lease.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

__all__ = ["DEFAULTS", "MAX_MESSAGE", "MAX_MESSAGE_BYTES", "MODES", "SHARED_MEMORY", "ConfigError",
           "ZenohOptions", "make_config", "zenoh_error"]

MODES = ("peer", "client", "router")
DEFAULTS: dict[str, object] = {
    "connect/retry": {"period_init_ms": 250, "period_max_ms": 2000, "period_increase_factor": 2},
}


SHARED_MEMORY = "transport/shared_memory/enabled"
# No message above 50 MiB is taken off a link (the largest valid one, a 4096x4096 bgr8 frame,
# is 48 MiB: messages.MAX_PAYLOAD). Zenoh's default, 1 GiB, let one message cost a worker or
# a dashboard twice its size before the payload check refused it, and they kept the memory: a
# 300 MB frame left each 300 MB larger. Above the cap Zenoh drops the message; the link stays.
MAX_MESSAGE = "transport/link/rx/max_message_size"
MAX_MESSAGE_BYTES = 50 << 20
# A config file is read whole and its nesting parsed recursively by Zenoh: /dev/zero took 4 GB
# before failing, 27 MB of config 2.2 GB, and 50,000 nested objects crashed the process
# (SIGSEGV). Zenoh's own configs are a few KB, nested 5 deep.
MAX_CONFIG_BYTES = 1 << 20
MAX_CONFIG_DEPTH = 64


class ConfigError(ValueError):
    """A configuration file or option Zenoh does not accept."""


@dataclass(frozen=True)
class ZenohOptions:
    """What the common command-line options say about the Zenoh session.

    ``None`` (or empty) means "leave Zenoh's value (or the config file's) alone".
    """

    mode: str | None = None
    connect: Sequence[str] = field(default_factory=tuple)
    listen: Sequence[str] = field(default_factory=tuple)
    config_file: str | Path | None = None
    multicast_scouting: bool | None = None
    gossip: bool | None = None


_COMMENTS = re.compile(r"/\*.*?\*/|//[^\n]*", re.S)


def _nesting(text: str) -> int:
    """The deepest nesting of ``{`` and ``[`` in a JSON5 (or YAML flow) text, outside its
    strings and comments."""
    depth = deepest = 0
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c in "\"'":
            i += 1
            while i < n and text[i] != c:
                i += 2 if text[i] == "\\" else 1
        elif text.startswith("//", i) or c == "#":
            i = text.find("\n", i)
            i = n if i < 0 else i
        elif text.startswith("/*", i):
            i = text.find("*/", i + 2)
            i = n if i < 0 else i + 1
        elif c in "{[":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "}]":
            depth -= 1
        i += 1
    return deepest


def _read_config_file(path: str | Path) -> str:
    """A config file's text, checked before Zenoh parses it: a regular file of at most
    :data:`MAX_CONFIG_BYTES`, nested at most :data:`MAX_CONFIG_DEPTH` deep."""
    path = Path(path)
    try:
        if not path.is_file():
            raise ConfigError(f"Zenoh config {path}: not a regular file" if path.exists()
                              else f"Zenoh config {path}: no such file")
        with path.open("rb") as f:
            data = f.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"cannot read Zenoh config {path}: {exc.strerror or exc}") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ConfigError(f"Zenoh config {path}: larger than {MAX_CONFIG_BYTES >> 20} MiB")
    text = data.decode("utf-8", errors="replace")
    if _nesting(text) > MAX_CONFIG_DEPTH:
        raise ConfigError(f"Zenoh config {path}: nested more than {MAX_CONFIG_DEPTH} deep")
    return text


def _sets(text: str, name: str) -> bool:
    """Whether a JSON5 config's text has a ``name`` key outside its comments: where Zenoh has a
    default of its own, whether the file chose the value is read from the file itself."""
    pattern = r"""["']?\b""" + re.escape(name) + r"""["']?\s*:"""
    return re.search(pattern, _COMMENTS.sub("", text)) is not None


def make_config(options: ZenohOptions | None = None, **overrides) -> zenoh.Config:
    """Build a ``zenoh.Config`` from options (keyword arguments override fields of ``options``).

    Raises
    ------
    ConfigError
        For an unreadable config file, an unknown mode or an endpoint Zenoh rejects.
    """
    opts = options or ZenohOptions()
    if overrides:
        opts = ZenohOptions(**{**opts.__dict__, **overrides})
    text = _read_config_file(opts.config_file) if opts.config_file else ""
    try:
        conf = zenoh.Config.from_file(str(opts.config_file)) if opts.config_file else zenoh.Config()
    except Exception as exc:  # zenoh.ZError, or an OS error surfaced by zenoh
        raise ConfigError(f"cannot load Zenoh config {opts.config_file}: {zenoh_error(exc)}") \
            from None
    settings: list[tuple[str, object]] = [("timestamping/enabled", True)]
    for key, value in DEFAULTS.items():
        if json.loads(conf.get_json(key)) is None:
            settings.append((key, value))
    # Zenoh's own defaults (shared memory on, 1 GiB messages) unless the file chose its own
    if not _sets(text, "shared_memory"):
        settings.append((SHARED_MEMORY, False))
    if not _sets(text, "max_message_size"):
        settings.append((MAX_MESSAGE, MAX_MESSAGE_BYTES))
    if opts.mode is not None:
        if opts.mode not in MODES:
            raise ConfigError(f"unknown Zenoh mode {opts.mode!r}; choose one of {', '.join(MODES)}")
        settings.append(("mode", opts.mode))
    if opts.connect:
        settings.append(("connect/endpoints", list(opts.connect)))
    if opts.listen:
        settings.append(("listen/endpoints", list(opts.listen)))
    if opts.multicast_scouting is not None:
        settings.append(("scouting/multicast/enabled", opts.multicast_scouting))
    if opts.gossip is not None:
        settings.append(("scouting/gossip/enabled", opts.gossip))
    for key, value in settings:
        try:
            conf.insert_json5(key, json.dumps(value))
        except Exception as exc:
            # the place is in the one-line JSON made of the value here, not in a file: left out
            raise ConfigError(f"Zenoh rejects {key} = {json.dumps(value)}: "
                              f"{zenoh_error(exc, place=False)}") from None
    return conf


_RUST_LOCATION = re.compile(r"\s+at /\S+\.rs:\d+\.?")
# a config parser's report: "--> LINE:COLUMN", a drawing of the line, "= what it expected"
_PARSER_PLACE = re.compile(r"-->\s*(\d+):(\d+)")
_PARSER_SAYS = re.compile(r"^\s*=\s*(.+)$", re.M)
# a value the config refuses, in Rust's debug form: `Json5Err(Message { msg: "...", location:
# Some(Location { line: 1, column: 2 }) })` or `JSON error: Message { ... }`
# (the message is read as a Rust string literal, up to its closing quote: two such blocks in one
# error are two messages, not one that spans both)
_JSON_MESSAGE = re.compile(r'Message \{ msg: "((?:[^"\\]|\\.)*)", location: (?:Some\(Location '
                           r'\{ line: (\d+), column: (\d+) \}\)|None) \}', re.S)
# Rust's escapes of a quote and a backslash in such a message
_RUST_ESCAPE = re.compile(r'\\(["\\])')


def zenoh_error(exc: BaseException, place: bool = True) -> str:
    """A Zenoh error's text for a user, on one line: without the Rust source locations it
    carries, a config parser's drawing of the line at fault (six lines) said as the place
    and what the parser expected there, and a refused value's message without the Rust
    structure around it (its line and column first, unless ``place`` is false)."""
    text = _RUST_LOCATION.sub("", str(exc)).strip()
    where, says = _PARSER_PLACE.search(text), _PARSER_SAYS.search(text)
    if where and says:
        return f"line {where[1]}, column {where[2]}: {says[1].strip()}"
    message = _JSON_MESSAGE.search(text)
    if message:
        # Rust's escapes of a quote and a backslash undone, in one pass (a value's `\"` is
        # `\\\"` there); a newline's or a tab's kept as `\n`, `\t`: the message stays one line
        text = _RUST_ESCAPE.sub(r"\1", message[1]).strip()
        if place and message[2]:
            text = f"line {message[2]}, column {message[3]}: {text}"
    return " ".join(line.strip() for line in text.splitlines() if line.strip())
