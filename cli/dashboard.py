"""``asnn dashboard``: the fleet in a browser (clients.dashboard), with the common Zenoh options."""

from __future__ import annotations

import argparse
import logging
import sys

from cli.arguments import host_address, port, seconds
from cli.session import (EXIT_NO_ROUTER, add_zenoh_options, fail, open_session, router_watch,
                         setup_logging, stop_on_signals, zenoh_config)
from clients.dashboard import HOLD_S
from clients.fleet import STALE_S
from service.config import ConfigError

__all__ = ["register"]

log = logging.getLogger("asnn")


def serve_fleet(args: argparse.Namespace, store, server, name: str, url: str, *,
                refusals: bool = False, on_router=None) -> int:
    """Feed ``store`` from the fleet's subscribers (``refusals``: the workers' refusal notices
    too) while ``server`` (a context manager that serves it) runs, until SIGINT or SIGTERM;
    ``server`` is closed on every path. ``on_router`` is told whether the session reaches its
    router (:class:`service.link.RouterWatch`)."""
    from clients.fleet import FleetSubscriber

    try:
        config = zenoh_config(args)
        session = open_session(config)
    except ConfigError as exc:
        server.close()
        return fail(args.command, str(exc))
    stop = stop_on_signals()
    # the subscriber closed first: the server (and a Foxglove bridge's channels) would take
    # samples still arriving after it was closed
    with session, router_watch(session, name, config, on_change=on_router, args=args,
                               stop=stop) as watch, server, \
            FleetSubscriber(session, store, refusals=refusals) as subscriber:
        print(f"{name} on {url} showing {', '.join(subscriber.keys)}", file=sys.stderr,
              flush=True)
        while not stop.wait(0.5):
            pass
    log.info("%s stopped: received %s, invalid %s, skipped %s", name, dict(store.received),
             dict(store.invalid), dict(store.skipped))
    return EXIT_NO_ROUTER if watch.gave_up else 0


def cmd_dashboard(args: argparse.Namespace) -> int:
    from clients.dashboard import DashboardServer, FleetStore

    setup_logging(args)
    store = FleetStore(args.prefix, stale_after=args.stale_after, hold=args.hold)
    try:
        server = DashboardServer(store, args.host, args.port)
    except OSError as exc:  # the port is taken, or the address is not ours
        return fail(args.command,
                    f"cannot serve on {args.host}:{args.port}: {exc.strerror or exc}")
    host, port = server.address
    return serve_fleet(args, store, server, "dashboard", f"http://{host}:{port}/",
                       refusals=True, on_router=store.router_changed)


def register(subparsers) -> None:
    p = subparsers.add_parser("dashboard", help="the fleet in a web browser",
                              description="Serve a live page showing every robot on "
                              "<prefix>/*/response, warning, preview and refused: thumbnail "
                              "with the looming targets, spike-rate sparkline, collision and stale "
                              "markers, and the latest warnings. Every asset comes from the "
                              "package (works offline).")
    p.add_argument("--port", type=port, default=8080,
                   help="HTTP port (default: %(default)s; 0 picks a free one)")
    p.add_argument("--host", default="127.0.0.1", type=host_address,
                   help="address to serve on (default: %(default)s; 0.0.0.0 for every "
                        "interface, as in a container)")
    p.add_argument("--stale-after", type=seconds, default=STALE_S, metavar="SECONDS",
                   help="mark a robot stale after SECONDS without a response, whatever previews "
                        "its camera still sends (default: %(default)s)")
    p.add_argument("--hold", type=seconds, default=HOLD_S, metavar="SECONDS",
                   help="keep a robot in the collision state for SECONDS (camera clock) after "
                        "its latest warning (default: %(default)s)")
    add_zenoh_options(p, watched=True)
    p.set_defaults(func=cmd_dashboard)
