"""Export a triangle mesh with per-vertex colours to PLY or OBJ (through trimesh).

Colours are stored as 8-bit values, as PLY viewers expect:

* float colours are taken as linear values in [0, 1]. They are clipped to [0, 1]
  (the renderer neither clamps nor encodes, so out-of-range values do occur).
  With ``gamma``, the pure power ``c ** (1 / gamma)`` is applied (2.2 for
  AlbedoMM's display convention). Then they are quantised as
  ``round(255 c)``. Without ``gamma``, the file holds linear values;
* uint8 colours are written unchanged (``gamma`` is then an error, as they are
  taken to be encoded already).

PLY is binary little-endian, with float32 x y z and uchar red green blue alpha
(alpha 255). OBJ holds ``v x y z r g b`` with colours in [0, 1] (8 decimals,
enough to recover the 8-bit value). Files are written atomically.

This module imports only :mod:`albedo_model.errors` and
:mod:`albedo_model.io.atomic` (and trimesh).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.atomic import atomic_path

__all__ = ["MESH_SUFFIXES", "colours_to_uint8", "write_mesh"]

#: file suffixes write_mesh understands (case-insensitive)
MESH_SUFFIXES = (".ply", ".obj")


def colours_to_uint8(colours: np.ndarray, *, gamma: float | None = None) -> np.ndarray:
    """Per-vertex colours as 8-bit RGB, following the module's rules.

    Parameters
    ----------
    colours : (n, 3) float or uint8
        Linear RGB in [0, 1] (clipped), or already-encoded 8-bit RGB.
    gamma : float, optional
        Encode float colours with ``c ** (1 / gamma)`` before quantising.

    Returns
    -------
    (n, 3) uint8
    """
    colours = np.asarray(colours)
    if colours.ndim != 2 or colours.shape[1] != 3:
        raise InputError(f"colours must have shape (n, 3), got {colours.shape}")
    if colours.dtype == np.uint8:
        if gamma is not None:
            raise InputError("gamma applies to float (linear) colours; uint8 colours are "
                             "written unchanged")
        return colours.copy()
    if not np.issubdtype(colours.dtype, np.floating):
        raise InputError(f"colours must be float (linear, [0, 1]) or uint8, got {colours.dtype}")
    if not np.all(np.isfinite(colours)):
        raise InputError("colours contain NaN or infinite values")
    c = np.clip(colours.astype(np.float64), 0.0, 1.0)
    if gamma is not None:
        if not gamma > 0:
            raise InputError(f"gamma must be positive, got {gamma}")
        c = c ** (1.0 / gamma)
    return np.rint(c * 255.0).astype(np.uint8)


def write_mesh(path: str | os.PathLike, vertices: np.ndarray, triangles: np.ndarray,
               colours: np.ndarray | None = None, *, gamma: float | None = None) -> None:
    """Write a coloured triangle mesh; the format follows the suffix (.ply or .obj).

    Parameters
    ----------
    path : path-like
        Destination ending in ``.ply`` or ``.obj``; its folder must exist.
    vertices : (n, 3) float
        Vertex positions (any frame; model-frame mm for model instances).
    triangles : (m, 3) int
        0-based vertex indices, counter-clockwise seen from outside.
    colours : (n, 3) float or uint8, optional
        Per-vertex colours (see the module docstring for clipping and ``gamma``).
    gamma : float, optional
        Display encoding of float colours, e.g. 2.2.

    Raises
    ------
    FormatError
        Unsupported suffix.
    InputError
        Wrong shapes, out-of-range indices, non-finite values.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise FormatError(path, f"unsupported mesh format {path.suffix or '(none)'!r} "
                                f"(use {' or '.join(MESH_SUFFIXES)})")
    vertices = np.asarray(vertices, np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) == 0:
        raise InputError(f"vertices must have shape (n, 3), n > 0, got {vertices.shape}")
    if not np.all(np.isfinite(vertices)):
        raise InputError("vertices contain NaN or infinite values")
    triangles = np.asarray(triangles)
    if triangles.ndim != 2 or triangles.shape[1] != 3 or not np.issubdtype(
            triangles.dtype, np.integer):
        raise InputError(f"triangles must be an (m, 3) integer array, got {triangles.shape} "
                         f"{triangles.dtype}")
    if triangles.size and (triangles.min() < 0 or triangles.max() >= len(vertices)):
        raise InputError(f"triangle indices must lie in [0, {len(vertices)})")
    rgb = None
    if colours is not None:
        rgb = colours_to_uint8(colours, gamma=gamma)
        if len(rgb) != len(vertices):
            raise InputError(f"{len(rgb)} colours for {len(vertices)} vertices")
    elif gamma is not None:
        raise InputError("gamma given without colours")

    import trimesh  # heavy import, only needed here

    mesh = trimesh.Trimesh(vertices=vertices, faces=triangles.astype(np.int64),
                           process=False, validate=False)
    if rgb is not None:
        rgba = np.concatenate([rgb, np.full((len(rgb), 1), 255, np.uint8)], axis=1)
        mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=rgba)
    if suffix == ".ply":
        data = trimesh.exchange.ply.export_ply(mesh, encoding="binary", vertex_normal=False)
    else:
        data = trimesh.exchange.obj.export_obj(
            mesh, include_normals=False, include_color=rgb is not None, include_texture=False)
    with atomic_path(path) as tmp:
        if isinstance(data, str):
            tmp.write_text(data, encoding="utf-8")
        else:
            tmp.write_bytes(data)
