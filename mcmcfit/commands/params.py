"""``mcmcfit params``: render-parameter (``.rps``) file utilities.

``mcmcfit params convert IN.rps -o OUT.rps`` reads any version (V1-V4) and
writes V4 (plus this project's ``specularExponent``). Bad input is a
:class:`albedo_model.errors.FormatError`; nothing is written then.

This module imports only :mod:`albedo_model.io.rps`.
"""

from __future__ import annotations

import argparse

from albedo_model.io.rps import read_rps, write_rps

__all__ = ["register", "convert"]


def convert(args: argparse.Namespace) -> int:
    """Read ``args.input`` (any ``.rps`` version) and write it as V4 to ``args.output``."""
    params = read_rps(args.input)
    write_rps(args.output, params)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``params`` command and its subcommands."""
    parser = subparsers.add_parser(
        "params", help="render-parameter (.rps) file utilities",
        description="Render-parameter (.rps) file utilities.",
    )
    sub = parser.add_subparsers(dest="params_command", metavar="SUBCOMMAND", required=True)
    conv = sub.add_parser(
        "convert", help="rewrite an .rps file of any version (V1-V4) as V4",
        description="Read an .rps file of any version (V1-V4) and write it as V4.",
    )
    conv.add_argument("input", metavar="IN.rps", help="render parameters, any version")
    conv.add_argument("-o", "--output", metavar="OUT.rps", required=True,
                      help="V4 output file (written atomically; may equal the input)")
    conv.set_defaults(func=convert)
