"""``asnn foxglove``: the live fleet in the Foxglove app (clients.foxglove), with the common Zenoh
options."""

from __future__ import annotations

import argparse

from cli.arguments import fleet_size, host_address, mcap_output, megabytes, port
from cli.dashboard import serve_fleet
from cli.session import add_zenoh_options, fail, setup_logging

__all__ = ["register"]


def cmd_foxglove(args: argparse.Namespace) -> int:
    setup_logging(args)
    if args.mcap_max_mb is not None and args.mcap is None:
        return fail(args.command,
                    "--mcap-max-mb bounds a recording: give it with --mcap OUT.mcap")
    try:
        from clients.foxglove import FoxgloveBridge
    except ImportError as exc:  # the message names the extra to install
        return fail(args.command, str(exc))
    try:
        bound = {} if args.mcap_max_mb is None else {"record_max_bytes": args.mcap_max_mb * 1e6}
        bridge = FoxgloveBridge(args.prefix, host=args.host, port=args.port,
                                max_robots=args.max_robots, record=args.mcap, **bound)
    except OSError as exc:
        return fail(args.command, str(exc))
    return serve_fleet(args, bridge, bridge, "foxglove", bridge.url, refusals=True,
                       on_router=bridge.router_changed)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "foxglove", help="the fleet live in the Foxglove app",
        description="Serve every robot seen on <prefix>/*/response, warning and preview to the "
                    "Foxglove app over its WebSocket protocol (Foxglove SDK): per robot the "
                    "preview image, the targets as image annotations, the response numbers and "
                    "the warnings, on /<prefix>/<robot>/... topics, and as problems the "
                    "robots gone stale, the workers' refusals (<prefix>/*/refused) and a lost "
                    "router (docs/foxglove.md). Needs the 'ros' extra.")
    p.add_argument("--port", type=port, default=8765,
                   help="WebSocket port (default: %(default)s; 0 picks a free one)")
    p.add_argument("--host", default="127.0.0.1", type=host_address,
                   help="address to serve on (default: %(default)s; the protocol has no "
                        "authentication, so 0.0.0.0 shows the fleet to the whole network)")
    p.add_argument("--max-robots", type=fleet_size, default=256, metavar="N",
                   help="robots served at once; messages of more are counted and dropped "
                        "(default: %(default)s)")
    p.add_argument("--mcap", type=mcap_output, default=None, metavar="OUT.mcap",
                   help="also record what the viewers are sent (every robot's previews, "
                        "annotations, responses and warnings) to this new file, for a later "
                        "look in Foxglove; finished when the server stops")
    p.add_argument("--mcap-max-mb", type=megabytes, default=None, metavar="MB",
                   help="stop recording once the file reaches this size (default: 1000)")
    add_zenoh_options(p, watched=True)
    p.set_defaults(func=cmd_foxglove)
