"""Reading the JSON files of a capture (camera files, ``lightstage.json``, ``subject.json``).

Errors name the file: :class:`~albedo_model.errors.InputError` when it is missing,
:class:`~albedo_model.errors.FormatError` when it is not JSON (or not an object).

This module imports only :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from albedo_model.errors import FormatError, InputError

__all__ = ["read_json_file", "read_json_object"]


def read_json_file(path: str | os.PathLike) -> Any:
    """Parse a JSON file.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    Any
        The parsed value (object, list, number, ...).

    Raises
    ------
    InputError
        The file does not exist.
    FormatError
        The file is not valid UTF-8 JSON.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: file not found")
    try:
        return json.loads(p.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FormatError(p, f"not a JSON file ({exc.__class__.__name__})") from None


def read_json_object(path: str | os.PathLike) -> dict:
    """Parse a JSON file that must hold one object.

    Raises
    ------
    InputError
        The file does not exist.
    FormatError
        The file is not valid UTF-8 JSON, or holds something other than an object.
    """
    data = read_json_file(path)
    if not isinstance(data, dict):
        raise FormatError(Path(path), "must hold a JSON object")
    return data
