"""The ``mapmatch`` command line: one sub-command per module of this package."""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from typing import TYPE_CHECKING

from roadnets.errors import MapMatchError

if TYPE_CHECKING:
    from collections.abc import Sequence

__all__ = ["main"]

#: Sub-command modules; each has ``add_parser(subparsers)`` and ``run(args) -> int``.
COMMANDS = ("match", "serve", "network", "simulate", "evaluate", "fuse", "bench")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command."""
    parser = argparse.ArgumentParser(
        prog="mapmatch",
        description="Match fused vehicle traces onto OpenStreetMap roads.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        module = importlib.import_module(f"mapmatch.cli.{name}")
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """
    Run the command line; return the process exit code.

    Errors the project raises on purpose print as one line (``mapmatch: error: ...``) with
    exit code 2; they never show a traceback.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        return int(args.run(args))
    except MapMatchError as exc:
        print(f"mapmatch: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("mapmatch: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `mapmatch ... | head`: the reader left; not an error of ours
        # point stdout at devnull so the interpreter's final flush does not raise again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, as a shell reports it
