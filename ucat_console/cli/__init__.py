"""The ``ucat-console`` command: one sub-command module per feature.

Each module in :data:`COMMANDS` defines ``register(subparsers)``, which adds its
sub-command(s) with ``set_defaults(func=...)``; ``func(args)`` returns the exit status.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from ucat_console.backend.dependencies import UnsupportedVersion

#: sub-command modules under ucat_console.cli
COMMANDS = ["bench", "devices", "sessions", "replay", "identify", "experiment", "sweep", "run", "manoeuvres", "prepare",
            "paths"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ucat-console",
        description="Operator console and onboard controller for the U-CAT robot.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"ucat_console.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    if not args.verbose:
        # the CANopen stack logs every NMT step at INFO; websockets logs each page load it
        # serves as "connection rejected (200 OK)" and its listening address beside viser's box
        for name in ("canopen", "websockets.server"):
            logging.getLogger(name).setLevel(logging.WARNING)
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:  # output piped into e.g. `head`
        sys.stderr.close()
        return 0
    except (ValueError, OSError, UnsupportedVersion) as e:  # bad input, a file that cannot be read or
        # written, a library outside its supported range
        print(f"ucat-console: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
