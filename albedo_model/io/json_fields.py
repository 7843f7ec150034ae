"""Typed access to fields of parsed JSON objects, with path-naming errors.

Used by the ``.rps`` readers: every accessor raises :class:`FieldError` whose
message names the dotted path of the offending field (``camera.sensorSize``),
which the readers turn into :class:`albedo_model.errors.FormatError`.

This module imports nothing from the project.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = [
    "FieldError", "get_object", "get_number", "get_int", "get_bool", "get_string",
    "get_vector", "get_number_list", "get_rows",
]


class FieldError(ValueError):
    """A JSON field is missing or has the wrong type; the message says which."""


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _require(obj: dict[str, Any], key: str, where: str) -> Any:
    if key not in obj:
        raise FieldError(f"missing field {_join(where, key)}")
    return obj[key]


def _as_number(value: Any, path: str) -> float:
    # bool is an int subclass in Python, but JSON true/false is not a number
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise FieldError(f"{path} must be a number, got {_describe(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise FieldError(f"{path} must be finite, got {x}")
    return x


def _describe(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "an object"
    return repr(value)


def get_object(obj: dict[str, Any], key: str, where: str = "") -> dict[str, Any]:
    """Return the JSON object at ``obj[key]``."""
    value = _require(obj, key, where)
    if not isinstance(value, dict):
        raise FieldError(f"{_join(where, key)} must be an object, got {_describe(value)}")
    return value


def get_number(obj: dict[str, Any], key: str, where: str = "") -> float:
    """Return the finite number at ``obj[key]`` as a Python float (ints are accepted)."""
    return _as_number(_require(obj, key, where), _join(where, key))


def get_int(obj: dict[str, Any], key: str, where: str = "") -> int:
    """Return the integer at ``obj[key]`` (an integral float such as ``250.0`` is accepted)."""
    path = _join(where, key)
    x = _as_number(_require(obj, key, where), path)
    if x != int(x):
        raise FieldError(f"{path} must be an integer, got {x!r}")
    return int(x)


def get_bool(obj: dict[str, Any], key: str, where: str = "") -> bool:
    """Return the JSON boolean at ``obj[key]``."""
    value = _require(obj, key, where)
    if not isinstance(value, bool):
        raise FieldError(f"{_join(where, key)} must be true or false, got {_describe(value)}")
    return value


def get_string(obj: dict[str, Any], key: str, where: str = "") -> str:
    """Return the JSON string at ``obj[key]``."""
    value = _require(obj, key, where)
    if not isinstance(value, str):
        raise FieldError(f"{_join(where, key)} must be a string, got {_describe(value)}")
    return value


def get_vector(obj: dict[str, Any], key: str, n: int, where: str = "") -> tuple[float, ...]:
    """Return the list of exactly ``n`` numbers at ``obj[key]`` as a tuple of floats."""
    path = _join(where, key)
    value = _require(obj, key, where)
    if not isinstance(value, list) or len(value) != n:
        raise FieldError(f"{path} must be a list of {n} numbers, got {_describe(value)}")
    return tuple(_as_number(v, f"{path}[{i}]") for i, v in enumerate(value))


def get_number_list(obj: dict[str, Any], key: str, where: str = "") -> np.ndarray:
    """Return the list of numbers at ``obj[key]`` as a (k,) float64 array (k may be 0)."""
    path = _join(where, key)
    value = _require(obj, key, where)
    if not isinstance(value, list):
        raise FieldError(f"{path} must be a list of numbers, got {_describe(value)}")
    return np.array([_as_number(v, f"{path}[{i}]") for i, v in enumerate(value)], np.float64)


def get_rows(obj: dict[str, Any], key: str, width: int, where: str = "") -> np.ndarray:
    """Return the ``width``-number lists at ``obj[key]`` as a (k, width) float64 array."""
    path = _join(where, key)
    value = _require(obj, key, where)
    if not isinstance(value, list):
        raise FieldError(f"{path} must be a list of {width}-vectors, got {_describe(value)}")
    rows = np.zeros((len(value), width), np.float64)
    for i, row in enumerate(value):
        if not isinstance(row, list) or len(row) != width:
            raise FieldError(f"{path}[{i}] must be a list of {width} numbers, got {_describe(row)}")
        rows[i] = [_as_number(v, f"{path}[{i}][{j}]") for j, v in enumerate(row)]
    return rows
