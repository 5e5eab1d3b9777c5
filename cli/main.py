"""Entry point of the ``asnn`` command: one sub-command per module of this package."""

from __future__ import annotations

import argparse
import importlib
import sys

# Each module defines ``register(subparsers)``, adding its sub-commands with ``func`` set.
COMMAND_MODULES = ["cli.detect", "cli.scene", "cli.net", "cli.evaluate", "cli.bench",
                   "cli.dashboard", "cli.foxglove"]


def build_parser() -> argparse.ArgumentParser:
    """The full parser (also used by tests to check docker-compose commands)."""
    parser = argparse.ArgumentParser(
        prog="asnn", description="Approach-Sensitive Neural Network collision detection")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
