"""Spectral tables from CSV files: camera sensitivities and light spectra.

The format of the Jiang et al. 2013 camera database (e.g. ``Nikon_D200.csv``
of ``butcherg/ssf-data``, CC BY-NC-SA, so never shipped here): ``#`` comment
lines, then rows ``lambda,R,G,B`` in nm; a light spectrum has rows
``lambda,power``. Tables are resampled onto the spectral grid of
:mod:`pipeline.lightstage.colour`.

Imports only :mod:`albedo_model.errors` and :mod:`pipeline.lightstage.colour`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from albedo_model.errors import FormatError, InputError
from pipeline.lightstage.colour import DEFAULT_GRID, spectral_grid

__all__ = ["read_spectral_csv"]


def read_spectral_csv(
    path: str | os.PathLike, columns: int, grid: tuple[float, float, float] = DEFAULT_GRID
) -> np.ndarray:
    """Read a spectral table ``wavelength,v1[,v2,...]`` (nm) and resample it onto ``grid``.

    The format of the Jiang et al. 2013 camera database (``Nikon_D200.csv``:
    ``#`` comment lines, then rows ``lambda,R,G,B``); an illuminant file has one
    value column. Blank lines and ``#`` lines are skipped; a first row that
    is not numeric is taken as a header. Values are linearly interpolated.

    Parameters
    ----------
    path : path-like
    columns : int
        Number of value columns expected (3 for a camera, 1 for a light).
    grid : (start, stop, step) in nm

    Returns
    -------
    (D, columns) float64 array, read-only

    Raises
    ------
    InputError, FormatError
        Missing file; malformed rows; wavelengths not increasing; the table
        does not cover the grid; negative values.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: file not found")
    rows = []
    for number, line in enumerate(p.read_text(errors="replace").splitlines(), 1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = text.replace(",", " ").replace(";", " ").split()
        try:
            values = [float(f) for f in fields]
        except ValueError:
            if not rows:
                continue  # header line
            raise FormatError(p, f"line {number}: not a row of numbers") from None
        if len(values) != columns + 1:
            raise FormatError(p, f"line {number}: expected {columns + 1} values "
                                 f"(wavelength and {columns}), got {len(values)}")
        rows.append(values)
    if len(rows) < 2:
        raise FormatError(p, "needs at least two rows of numbers")
    table = np.array(rows)
    wl = table[:, 0]
    if np.any(np.diff(wl) <= 0):
        raise FormatError(p, "wavelengths must increase strictly")
    if not np.all(np.isfinite(table)) or np.any(table[:, 1:] < 0):
        raise FormatError(p, "values must be finite and non-negative")
    target = spectral_grid(grid)
    if target[0] < wl[0] - 1e-9 or target[-1] > wl[-1] + 1e-9:
        raise FormatError(p, f"covers {wl[0]:g}-{wl[-1]:g} nm but the spectral grid needs "
                             f"{target[0]:g}-{target[-1]:g} nm")
    out = np.stack([np.interp(target, wl, table[:, 1 + c]) for c in range(columns)], axis=1)
    out.setflags(write=False)
    return out

