"""Registering the actions of a command group such as ``mcmcfit model`` or ``mcmcfit pipeline``.

This module imports nothing from the project.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

__all__ = ["add_action"]


def add_action(actions: argparse._SubParsersAction, name: str,
               run: Callable[[argparse.Namespace], int], *, help: str, description: str,
               arguments: Callable[[argparse.ArgumentParser], None] | None = None,
               ) -> argparse.ArgumentParser:
    """Add one action to a command group and return its parser.

    Parameters
    ----------
    actions : argparse._SubParsersAction
        The group's ``add_subparsers`` result.
    name : str
        The action's name on the command line.
    run : callable
        ``run(args) -> exit status``, stored as the parsed arguments' ``func``.
    help : str
        One line for the group's ``--help``.
    description : str
        The paragraph of the action's own ``--help``.
    arguments : callable, optional
        ``arguments(parser)`` adds the action's arguments (e.g. a command module's
        ``add_arguments``); without it the caller adds them to the returned parser.

    Returns
    -------
    argparse.ArgumentParser
        The action's parser.
    """
    parser = actions.add_parser(name, help=help, description=description)
    if arguments is not None:
        arguments(parser)
    parser.set_defaults(func=run)
    return parser
