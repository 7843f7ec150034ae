"""The ``mcmcfit`` command line: argparse subcommands, one module each.

Each module in :mod:`mcmcfit.commands` exposes ``register(subparsers)``, which
adds its subcommand(s) and sets ``func(args) -> int`` as the handler. Project
errors (:class:`albedo_model.errors.AlbedoModelError`) become one line on
stderr and exit code 2.

This module imports :mod:`albedo_model.errors`; building the parser imports
:mod:`mcmcfit` (the version) and the :data:`COMMAND_MODULES` of :mod:`mcmcfit.commands`.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from albedo_model.errors import AlbedoModelError

__all__ = ["main", "build_parser"]

#: Command modules under ``mcmcfit.commands``, in help order.
COMMAND_MODULES = ("model", "params", "render", "landmarks", "fit", "demo", "texture", "pipeline",
                   "batch", "bench", "evaluate")


def build_parser() -> argparse.ArgumentParser:
    """Build the full argument parser with every available subcommand."""
    from mcmcfit import __version__

    parser = argparse.ArgumentParser(
        prog="mcmcfit",
        description="Posterior diffuse and specular face albedo from one photograph.",
    )
    parser.add_argument("--version", action="version", version=f"mcmcfit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"mcmcfit.commands.{name}")
        except ModuleNotFoundError as exc:  # command not part of this build
            if exc.name != f"mcmcfit.commands.{name}":
                raise
            continue
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except AlbedoModelError as exc:
        print(f"mcmcfit {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"mcmcfit {args.command}: error: {exc.filename or exc}: file not found", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"mcmcfit {args.command}: interrupted", file=sys.stderr)
        return 130
