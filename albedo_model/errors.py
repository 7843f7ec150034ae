"""Project exceptions.

Every user-facing failure is raised as a subclass of :class:`AlbedoModelError`
with a one-line message that names the file (when there is one) and the reason;
the command line turns it into a single line on stderr and a non-zero exit code.

This module imports nothing from the project.
"""

from __future__ import annotations

import os

__all__ = ["AlbedoModelError", "FormatError", "InputError"]


class AlbedoModelError(Exception):
    """Base class of every error the project raises on purpose."""


class FormatError(AlbedoModelError):
    """A file could not be read or written because of its content or layout.

    Parameters
    ----------
    path : str or os.PathLike
        The offending file.
    reason : str
        What is wrong, in a few words (``"missing dataset /shape/model/mean"``).
    """

    def __init__(self, path: str | os.PathLike | None, reason: str) -> None:
        self.path = None if path is None else os.fspath(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}" if self.path else reason)


class InputError(AlbedoModelError):
    """Invalid arguments or values (wrong shapes, unknown names, bad ranges)."""
