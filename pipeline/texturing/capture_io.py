"""Reading lightstage captures: registered meshes and view photographs.

Meshes: PLY/OBJ/OFF/STL through trimesh (vertex order kept, no merging), or a
MATLAB file holding ``V`` (n x 3) and 1-based ``F`` (m x 3), as the AlbedoMM
sample's ``FV.mat`` (v5 files through scipy, v7.3 files through h5py).
View photographs are read by :func:`albedo_model.io.image_io.read_image_pixels`
(8- or 16-bit integer pixels kept, no float copy of a 10-megapixel image),
several decoded in parallel threads.

This module imports only :mod:`albedo_model.errors` and
:mod:`albedo_model.io.image_io`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.image_io import read_image_pixels

__all__ = ["load_mesh", "load_view_images"]


def _mat_arrays(p: Path) -> tuple[np.ndarray, np.ndarray]:
    import scipy.io

    try:
        data = scipy.io.loadmat(p, variable_names=["V", "F"])
        return data.get("V"), data.get("F")
    except NotImplementedError:  # MATLAB v7.3 = HDF5, stored transposed
        import h5py

        with h5py.File(p, "r") as f:
            get = (lambda k: np.asarray(f[k]).T if k in f else None)
            return get("V"), get("F")
    except (ValueError, TypeError, OSError) as exc:
        raise FormatError(p, f"not a readable MATLAB file ({exc.__class__.__name__})") from None


def load_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a registered mesh.

    Parameters
    ----------
    path : path-like
        ``.mat`` (variables ``V`` and 1-based ``F``) or any mesh format trimesh reads.

    Returns
    -------
    vertices : (n, 3) float64
    triangles : (m, 3) int32, 0-based

    Raises
    ------
    InputError
        The file does not exist.
    FormatError
        Unreadable file, missing variables, wrong shapes or out-of-range indices.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: file not found")
    if p.suffix.lower() == ".mat":
        v, f = _mat_arrays(p)
        if v is None or f is None:
            raise FormatError(p, "needs variables 'V' (vertices) and 'F' (1-based triangles)")
        f = np.asarray(f)
        if not np.issubdtype(f.dtype, np.number) or (f != np.round(f)).any():
            raise FormatError(p, "'F' must hold integer vertex indices")
        f = f.astype(np.int64) - 1
    else:
        import trimesh

        try:
            mesh = trimesh.load(p, process=False, force="mesh")
        except Exception as exc:  # trimesh raises many types for bad files
            raise FormatError(p, f"not a readable mesh ({exc.__class__.__name__})") from None
        v, f = mesh.vertices, mesh.faces
    v = np.asarray(v, np.float64)
    f = np.asarray(f)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise FormatError(p, f"vertices must be an (n, 3) array, got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise FormatError(p, f"triangles must be an (m, 3) array, got {f.shape}")
    if f.min() < 0 or f.max() >= len(v):
        raise FormatError(p, f"triangle indices out of range for {len(v)} vertices")
    if not np.isfinite(v).all():
        raise FormatError(p, "vertices contain NaN or inf")
    return v, f.astype(np.int32)


def load_view_images(paths: Sequence[str | os.PathLike], threads: int = 2) -> list[np.ndarray]:
    """Read view photographs, decoded in ``threads`` threads.

    Parameters
    ----------
    paths : sequence of path-like
        The photographs, in view order.
    threads : int
        Decoding threads; 1 (or a single path) reads them one after the other.

    Returns
    -------
    list of (H, W, 3) uint8, uint16 or float arrays
        One per path, in order, as :func:`albedo_model.io.image_io.read_image_pixels`
        returns them (stored pixel type kept; grey replicated, alpha dropped).

    Raises
    ------
    InputError
        A file does not exist.
    FormatError
        A file is not a readable image, or has an unsupported pixel type or shape.
    """
    if threads <= 1 or len(paths) <= 1:
        return [read_image_pixels(p) for p in paths]
    with ThreadPoolExecutor(max_workers=threads) as pool:
        return list(pool.map(read_image_pixels, paths))
