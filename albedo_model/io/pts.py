"""iBUG 68-point ``.pts`` landmark files and their Basel landmark names.

File format (300-W / iBUG)::

    version: 1
    n_points:  68
    {
    x1 y1
    ...
    x68 y68
    }

**Coordinate convention.** The 300-W annotations are 1-based (Matlab): the
centre of the top-left pixel is (1, 1). This is also what menpo assumes; it
subtracts 1 on import. The render frame of this project (and of scalismo's
TLMS files) puts the centre of the top-left pixel at (0, 0), with x to the
right and y down. :func:`read_pts` therefore subtracts 1 from both coordinates
by default. Pass ``one_based=False`` for files written 0-based, such as dlib's
output.

**Numbering and sides.** iBUG numbers points 1..68, and "right" means the
subject's right, which appears on the image's left in a frontal photo: point 37
is the outer corner of the subject's right eye. Basel names use the same sides
("left" is the subject's left), so ``right.eye.corner_outer`` is iBUG 37. The
keys of :data:`IBUG68_TO_BASEL` are 0-based row indices into the (68, 2) array
(iBUG number − 1):

=====  ====  ===================================  ========================================
  row  iBUG  Basel name                           note
=====  ====  ===================================  ========================================
    8     9  center.chin.tip                      lowest point of the jaw contour
   19    20  right.eyebrow.bend.upper             middle of the brow, ≈ its arch (approx.)
   21    22  right.eyebrow.inner_upper            inner end of the subject's right brow
   22    23  left.eyebrow.inner_upper             inner end of the subject's left brow
   24    25  left.eyebrow.bend.upper              middle of the brow, ≈ its arch (approx.)
   30    31  center.nose.tip                      pronasale
   31    32  right.nose.wing.outer                lateral end of the nostril contour
   33    34  center.nose.attachement_to_philtrum  subnasale (Basel spelling)
   35    36  left.nose.wing.outer                 lateral end of the nostril contour
   36    37  right.eye.corner_outer
   39    40  right.eye.corner_inner
   42    43  left.eye.corner_inner
   45    46  left.eye.corner_outer
   48    49  right.lips.corner                    outer mouth corner
   50    51  right.lips.philtrum_ridge            peak of the cupid's bow
   51    52  center.lips.upper.outer
   52    53  left.lips.philtrum_ridge             peak of the cupid's bow
   54    55  left.lips.corner                     outer mouth corner
   57    58  center.lips.lower.outer
   62    63  center.lips.upper.inner
   66    67  center.lips.lower.inner
=====  ====  ===================================  ========================================

The brow ends have no exact Basel counterpart. iBUG's brow points lie on the
upper brow contour, so the inner ends (22, 23) are the Basel ``inner_upper``
points. The outer ends (18, 27) are not mapped, and the middle points (20, 25)
only approximate the Basel ``bend.upper`` arch. Jaw-contour points other than
the chin tip (they slide along the silhouette) and the eyelid points are not
mapped.

This module imports only :mod:`albedo_model.errors`,
:mod:`albedo_model.io.text_files` and :mod:`albedo_model.io.tlms`.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.text_files import read_text_file
from albedo_model.io.tlms import Landmark

__all__ = ["IBUG68_TO_BASEL", "read_pts", "parse_pts_text", "pts_to_landmarks"]

#: 0-based row of the (68, 2) iBUG array -> Basel landmark name (see module docstring)
IBUG68_TO_BASEL: dict[int, str] = {
    8: "center.chin.tip",
    19: "right.eyebrow.bend.upper",
    21: "right.eyebrow.inner_upper",
    22: "left.eyebrow.inner_upper",
    24: "left.eyebrow.bend.upper",
    30: "center.nose.tip",
    31: "right.nose.wing.outer",
    33: "center.nose.attachement_to_philtrum",
    35: "left.nose.wing.outer",
    36: "right.eye.corner_outer",
    39: "right.eye.corner_inner",
    42: "left.eye.corner_inner",
    45: "left.eye.corner_outer",
    48: "right.lips.corner",
    50: "right.lips.philtrum_ridge",
    51: "center.lips.upper.outer",
    52: "left.lips.philtrum_ridge",
    54: "left.lips.corner",
    57: "center.lips.lower.outer",
    62: "center.lips.upper.inner",
    66: "center.lips.lower.inner",
}


def parse_pts_text(text: str, *, one_based: bool = True, n_points: int | None = 68,
                   source: str | os.PathLike | None = None) -> np.ndarray:
    """Parse ``.pts`` text into pixel coordinates in the render frame.

    Parameters
    ----------
    text : str
        The file content.
    one_based : bool
        The file uses the 1-based 300-W convention (default); 1 is subtracted.
    n_points : int or None
        Required number of points (68 for iBUG); None accepts the header's count.
    source : path-like, optional
        Named in error messages.

    Returns
    -------
    (n, 2) float64
        (x, y) per point, x right, y down, top-left pixel centre at (0, 0).

    Raises
    ------
    FormatError
        Missing header or braces, a count mismatch or a non-numeric coordinate.
    """
    lines = [(i, ln.strip()) for i, ln in enumerate(text.splitlines(), start=1)]
    lines = [(i, ln) for i, ln in lines if ln]
    count = None
    k = 0
    while k < len(lines) and lines[k][1] != "{":
        key, _, value = lines[k][1].partition(":")
        if key.strip() == "n_points":
            try:
                count = int(value)
            except ValueError:
                raise FormatError(source, f"line {lines[k][0]}: bad n_points {value.strip()!r}"
                                  ) from None
        k += 1
    if k == len(lines):
        raise FormatError(source, "no '{' opening the point list (is this a .pts file?)")
    if count is None:
        raise FormatError(source, "missing 'n_points:' header")
    try:
        end = next(j for j in range(k + 1, len(lines)) if lines[j][1] == "}")
    except StopIteration:
        raise FormatError(source, "no '}' closing the point list") from None
    body = lines[k + 1:end]
    if len(body) != count:
        raise FormatError(source, f"header says {count} points, the list has {len(body)}")
    if n_points is not None and count != n_points:
        raise FormatError(source, f"expected {n_points} points, the file has {count}")
    points = np.zeros((count, 2), np.float64)
    for row, (lineno, ln) in enumerate(body):
        fields = ln.split()
        if len(fields) != 2:
            raise FormatError(source, f"line {lineno}: expected 2 coordinates, got {len(fields)}")
        for c, token in enumerate(fields):
            try:
                points[row, c] = float(token)
            except ValueError:
                raise FormatError(source, f"line {lineno}: coordinate {token!r} is not a number"
                                  ) from None
            if not math.isfinite(points[row, c]):
                raise FormatError(source, f"line {lineno}: coordinate {token!r} is not finite")
    return points - 1.0 if one_based else points


def read_pts(path: str | os.PathLike, *, one_based: bool = True, n_points: int | None = 68
             ) -> np.ndarray:
    """Read an iBUG ``.pts`` file; see :func:`parse_pts_text`.

    Returns
    -------
    (68, 2) float64
        Pixel coordinates in the render frame (0-based; 1 subtracted by default).
    """
    path = Path(path)
    text = read_text_file(path, "a .pts file")
    return parse_pts_text(text, one_based=one_based, n_points=n_points, source=path)


def pts_to_landmarks(points: np.ndarray, *, visible: bool = True) -> list[Landmark]:
    """Select the iBUG points that have a Basel name, as 2D landmarks.

    Parameters
    ----------
    points : (68, 2) float
        iBUG points in the render frame (as returned by :func:`read_pts`).
    visible : bool
        Visibility flag given to every landmark.

    Returns
    -------
    list of Landmark
        One per entry of :data:`IBUG68_TO_BASEL`, in iBUG order.
    """
    points = np.asarray(points, np.float64)
    if points.shape != (68, 2):
        raise InputError(f"expected (68, 2) iBUG points, got shape {points.shape}")
    return [Landmark(name, (float(points[i, 0]), float(points[i, 1])), visible)
            for i, name in sorted(IBUG68_TO_BASEL.items())]
