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

__all__ = ["DEFAULTS", "MODES", "SHARED_MEMORY", "ConfigError", "ZenohOptions", "make_config",
           "zenoh_error"]

MODES = ("peer", "client", "router")
DEFAULTS: dict[str, object] = {
    "connect/retry": {"period_init_ms": 250, "period_max_ms": 2000, "period_increase_factor": 2},
}


SHARED_MEMORY = "transport/shared_memory/enabled"


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
_SHARED_MEMORY_KEY = re.compile(r"""["']?\bshared_memory["']?\s*:""")


def _sets_shared_memory(text: str) -> bool:
    """Whether a JSON5 config's text has a ``shared_memory`` key outside its comments."""
    return bool(_SHARED_MEMORY_KEY.search(_COMMENTS.sub("", text)))


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
    try:
        conf = zenoh.Config.from_file(str(opts.config_file)) if opts.config_file else zenoh.Config()
    except Exception as exc:  # zenoh.ZError, or an OS error surfaced by zenoh
        raise ConfigError(f"cannot load Zenoh config {opts.config_file}: {zenoh_error(exc)}") \
            from None
    settings: list[tuple[str, object]] = [("timestamping/enabled", True)]
    for key, value in DEFAULTS.items():
        if json.loads(conf.get_json(key)) is None:
            settings.append((key, value))
    # Zenoh's own default is true, so whether the file chose it is read from the file itself
    if not (opts.config_file and _sets_shared_memory(
            Path(opts.config_file).read_text(encoding="utf-8", errors="replace"))):
        settings.append((SHARED_MEMORY, False))
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
            raise ConfigError(f"Zenoh rejects {key} = {json.dumps(value)}: {exc}") from None
    return conf


_RUST_LOCATION = re.compile(r"\s+at /\S+\.rs:\d+\.?")


def zenoh_error(exc: BaseException) -> str:
    """A Zenoh error's text for a user: without the Rust source locations it carries."""
    return _RUST_LOCATION.sub("", str(exc)).strip()
