"""Reading small UTF-8 text files (landmarks, render parameters) with the project's errors.

The text formats (``.pts``, ``.tlms``, ``.rps``) are read whole and decoded as
UTF-8, dropping a byte-order mark. A missing file raises the usual
``FileNotFoundError``; any other failure raises a one-line
:class:`~albedo_model.errors.FormatError` that names the file.

This module imports only :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import os
from pathlib import Path

from albedo_model.errors import FormatError

__all__ = ["read_text_file"]


def read_text_file(path: str | os.PathLike, expected: str) -> str:
    """Read a whole UTF-8 text file (a leading byte-order mark is dropped).

    Parameters
    ----------
    path : path-like
        The file.
    expected : str
        What the file should be, for the message about content that is not
        UTF-8: ``"a .pts file"`` gives ``"not UTF-8 text (is this a .pts file?)"``.

    Returns
    -------
    str
        The decoded text.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    FormatError
        The file cannot be read (``"cannot read: <reason>"``, e.g. a folder)
        or is not UTF-8 text.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise FormatError(path, f"cannot read: {exc.strerror or exc}") from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise FormatError(path, f"not UTF-8 text (is this {expected}?)") from None
