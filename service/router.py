"""A Zenoh router from the Python package, for machines without ``zenohd``."""

from __future__ import annotations

import zenoh

from .config import ZenohOptions, make_config

__all__ = ["DEFAULT_LISTEN", "open_router"]

DEFAULT_LISTEN = "tcp/[::]:7447"  # zenohd's default


def open_router(options: ZenohOptions | None = None) -> zenoh.Session:
    """Open a session in router mode (listening on ``DEFAULT_LISTEN`` unless told otherwise).

    The caller keeps it open for as long as the router should run (``with open_router(...)``).
    """
    options = options or ZenohOptions()
    listen = options.listen
    if not listen and not options.config_file:
        listen = (DEFAULT_LISTEN,)
    return zenoh.open(make_config(options, mode="router", listen=tuple(listen)))
