"""A Zenoh router from the Python package, for machines without ``zenohd``."""

from __future__ import annotations

import json

import zenoh

from .config import ZenohOptions, make_config

__all__ = ["DEFAULT_LISTEN", "listen_endpoints", "router_config"]

DEFAULT_LISTEN = "tcp/[::]:7447"  # zenohd's default


def router_config(options: ZenohOptions | None = None) -> zenoh.Config:
    """The router's configuration: ``options`` in router mode, listening on ``DEFAULT_LISTEN``
    unless the options or the config file say where. Open it with ``zenoh.open`` and keep the
    session open for as long as the router should run."""
    options = options or ZenohOptions()
    listen = options.listen
    if not listen and not options.config_file:
        listen = (DEFAULT_LISTEN,)
    return make_config(options, mode="router", listen=tuple(listen))


def listen_endpoints(config: zenoh.Config) -> list[str]:
    """The endpoints a router with ``config`` listens on (Zenoh's default when none is set)."""
    endpoints = json.loads(config.get_json("listen/endpoints"))
    if isinstance(endpoints, dict):  # per mode: {router: [...], peer: [...], client: [...]}
        endpoints = endpoints.get("router")
    return [str(e) for e in endpoints] if endpoints else [DEFAULT_LISTEN]
