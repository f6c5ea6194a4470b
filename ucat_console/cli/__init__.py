# PYTHON_ARGCOMPLETE_OK
"""The ``ucat-console`` command: one sub-command module per feature.

Each module in :data:`COMMANDS` defines ``register(subparsers)``, which adds its
sub-command(s) with ``set_defaults(func=...)``; ``func(args)`` returns the exit status.
Shell completion is argcomplete's (``eval "$(register-python-argcomplete ucat-console)"``):
the marker above lets its shell hook find the command, and :func:`main` hands it the parser.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from ucat_console import __version__
from ucat_console.backend.dependencies import UnsupportedVersion

#: sub-command modules under ucat_console.cli
COMMANDS = ["bench", "devices", "sessions", "replay", "identify", "experiment", "sweep", "run", "manoeuvres", "seek", "prepare",
            "paths", "config"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ucat-console",
        description="Operator console and onboard controller for the U-CAT robot.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"ucat_console.cli.{name}").register(sub)
    return parser


def complete(parser: argparse.ArgumentParser) -> None:
    """Answer a shell's completion request (argcomplete's, through its environment) and exit;
    nothing when there is none, or argcomplete is not installed."""
    try:
        import argcomplete
    except ImportError:  # a dependency, but the command works without it
        return
    argcomplete.autocomplete(parser)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    complete(parser)
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
