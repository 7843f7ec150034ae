"""TLMS landmark files (scalismo-faces): one landmark per line, 2D or 3D.

Format: whitespace-separated ``name visible x y`` (2D) or ``name visible x y z``
(3D); ``visible`` is an integer flag, > 0 meaning visible; empty lines are
skipped. 2D coordinates are pixels in the render frame (x right, y down,
origin at the top-left, pixel (i, j) sampled at the continuous point (i, j));
3D coordinates are model-frame millimetres. Names are Basel names; "left"
means the subject's left.

The writer uses ``%.17g`` (17 significant digits), so every float64 reads back
bit-exactly; scalismo's Java ``%.17g`` pads with zeros instead of printing the
17th digit, and both parse to the same doubles. Unlike scalismo (which parses
to float32), the reader keeps float64.

This module imports only :mod:`albedo_model.errors`,
:mod:`albedo_model.io.atomic` and :mod:`albedo_model.io.text_files`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.atomic import atomic_path
from albedo_model.io.text_files import read_text_file

__all__ = [
    "Landmark", "parse_tlms_text", "format_tlms_text", "read_tlms", "write_tlms",
    "landmarks_to_dict",
]


class Landmark(NamedTuple):
    """One named landmark: a 2D pixel position or a 3D model-frame point.

    Attributes
    ----------
    name : str
        Basel landmark name (no whitespace), e.g. ``"left.eye.corner_outer"``.
    point : tuple of 2 or 3 floats
        (x, y) in pixels or (x, y, z) in mm.
    visible : bool
        False for landmarks annotated as occluded.
    """

    name: str
    point: tuple[float, ...]
    visible: bool = True

    @property
    def dim(self) -> int:
        """2 or 3."""
        return len(self.point)


def _parse_number(token: str, what: str, lineno: int, source) -> float:
    try:
        x = float(token)
    except ValueError:
        raise FormatError(source, f"line {lineno}: {what} {token!r} is not a number") from None
    if not math.isfinite(x):
        raise FormatError(source, f"line {lineno}: {what} {token!r} is not finite")
    return x


def parse_tlms_text(text: str, dim: int | None = None,
                    source: str | os.PathLike | None = None) -> list[Landmark]:
    """Parse TLMS text (e.g. a file, or the text embedded in a MoMo HDF5 file).

    Parameters
    ----------
    text : str
        TLMS lines.
    dim : {2, 3}, optional
        Expected dimension. None: taken from the first landmark line (4 fields
        mean 2D, 5 mean 3D); every other line must match.
    source : path-like, optional
        Named in error messages.

    Returns
    -------
    list of Landmark
        In file order; points are float64 values as tuples.

    Raises
    ------
    FormatError
        A line with the wrong number of fields or a non-numeric value; the
        message names the source and the 1-based line number.
    """
    if dim not in (None, 2, 3):
        raise InputError(f"TLMS dimension must be 2 or 3, got {dim!r}")
    out: list[Landmark] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        if dim is None:
            if len(fields) not in (4, 5):
                raise FormatError(source, f"line {lineno}: expected 4 fields (name visible x y) "
                                          f"or 5 (name visible x y z), got {len(fields)}")
            dim = len(fields) - 2
        if len(fields) != dim + 2:
            layout = "name visible x y" if dim == 2 else "name visible x y z"
            raise FormatError(source, f"line {lineno}: expected {dim + 2} fields ({layout}) "
                                      f"for {dim}D landmarks, got {len(fields)}")
        visible = _parse_number(fields[1], "visibility flag", lineno, source) > 0
        point = tuple(_parse_number(t, "coordinate", lineno, source) for t in fields[2:])
        out.append(Landmark(fields[0], point, visible))
    return out


def _check_landmarks(landmarks: Sequence[Landmark]) -> int:
    dims = {len(lm.point) for lm in landmarks}
    if len(dims) > 1:
        raise InputError(f"landmarks mix dimensions {sorted(dims)}; a TLMS file is 2D or 3D")
    dim = dims.pop() if dims else 2
    if dim not in (2, 3):
        raise InputError(f"TLMS landmarks must be 2D or 3D, got {dim}D")
    for lm in landmarks:
        if not lm.name or any(c.isspace() for c in lm.name):
            raise InputError(f"landmark name {lm.name!r} is empty or contains whitespace")
        if not all(math.isfinite(float(v)) for v in lm.point):
            raise InputError(f"landmark {lm.name!r} has a non-finite coordinate {lm.point}")
    return dim


def format_tlms_text(landmarks: Iterable[Landmark]) -> str:
    """TLMS text of ``landmarks`` (all 2D or all 3D), one ``%.17g`` line each."""
    landmarks = list(landmarks)
    _check_landmarks(landmarks)
    lines = []
    for lm in landmarks:
        coords = " ".join(f"{float(v):.17g}" for v in lm.point)
        lines.append(f"{lm.name} {1 if lm.visible else 0} {coords}\n")
    return "".join(lines)


def read_tlms(path: str | os.PathLike, dim: int | None = None) -> list[Landmark]:
    """Read a TLMS file (2D or 3D, see :func:`parse_tlms_text`).

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    FormatError
        Not UTF-8 text, or a malformed line.
    """
    path = Path(path)
    text = read_text_file(path, "a TLMS landmark file")
    return parse_tlms_text(text, dim, path)


def write_tlms(path: str | os.PathLike, landmarks: Iterable[Landmark]) -> None:
    """Write landmarks (all 2D or all 3D) as a TLMS file, atomically.

    Raises
    ------
    InputError
        Mixed dimensions, a name with whitespace, or a non-finite coordinate.
    """
    text = format_tlms_text(landmarks)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def landmarks_to_dict(landmarks: Iterable[Landmark], *, visible_only: bool = False
                      ) -> dict[str, np.ndarray]:
    """``{name: (dim,) float64 point}``; with ``visible_only``, occluded ones are dropped.

    Raises
    ------
    InputError
        A name occurs twice.
    """
    out: dict[str, np.ndarray] = {}
    for lm in landmarks:
        if visible_only and not lm.visible:
            continue
        if lm.name in out:
            raise InputError(f"landmark {lm.name!r} occurs twice")
        out[lm.name] = np.array(lm.point, np.float64)
    return out
