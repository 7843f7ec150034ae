"""Texture coordinates of a model's mesh: a UV atlas, computed with xatlas or read from a file.

A UV atlas gives every triangle corner a point in the unit square, OBJ-style:
``uv`` (t, 2) holds the distinct texture points and ``uv_triangles`` (m, 3) the
index of each corner's point, triangle by triangle in the order of the mesh's
``triangles``. A mesh vertex on a seam between two charts has one texture point
per chart; :func:`uv_vertices` gives the mesh vertex of every texture point.

Conventions are OBJ's and Blender's: ``u`` to the right, ``v`` up, the texture
image's first row at ``v = 1``.

This module imports only :mod:`albedo_model.errors` (and xatlas, when an atlas is computed).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from albedo_model.errors import InputError

__all__ = ["ATLAS_PADDING", "ATLAS_RESOLUTION", "UVAtlas", "compute_uv_atlas", "uv_vertices"]

#: Texels of the square the charts are packed into by :func:`compute_uv_atlas`.
ATLAS_RESOLUTION = 1024
#: Empty texels (at :data:`ATLAS_RESOLUTION`) between two charts: bilinear sampling and
#: mip-mapping of a baked texture never mix two charts at this size and above.
ATLAS_PADDING = 4


@dataclasses.dataclass(frozen=True, eq=False)
class UVAtlas:
    """Texture coordinates of a triangle mesh.

    Parameters
    ----------
    uv : (t, 2) float array
        Texture points in [0, 1]^2 (``u`` right, ``v`` up).
    uv_triangles : (m, 3) int array
        Per triangle of the mesh, the texture point of each corner.
    """

    uv: np.ndarray
    uv_triangles: np.ndarray

    def __post_init__(self) -> None:
        """Validate and store read-only float64 / int32 copies."""
        uv = np.array(self.uv, np.float64)
        tri = np.array(self.uv_triangles)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise InputError(f"uv must have shape (t, 2), got {uv.shape}")
        if not np.all(np.isfinite(uv)) or (uv.size and (uv.min() < 0 or uv.max() > 1)):
            raise InputError("uv coordinates must be finite and in [0, 1]")
        if tri.ndim != 2 or tri.shape[1] != 3 or not np.issubdtype(tri.dtype, np.integer):
            raise InputError(f"uv_triangles must be an integer array (m, 3), got {tri.shape}")
        if tri.size and (tri.min() < 0 or tri.max() >= len(uv)):
            raise InputError(f"uv_triangles index out of range [0, {len(uv)})")
        uv.flags.writeable = False
        tri = tri.astype(np.int32)
        tri.flags.writeable = False
        object.__setattr__(self, "uv", uv)
        object.__setattr__(self, "uv_triangles", tri)

    @property
    def n_points(self) -> int:
        """Number of texture points (mesh vertices, plus one per extra chart at seams)."""
        return int(self.uv.shape[0])

    def check_mesh(self, triangles: np.ndarray, n_vertices: int) -> None:
        """Raise :class:`InputError` unless the atlas fits this mesh.

        Every triangle must have texture corners, and every texture point must
        belong to one mesh vertex only.
        """
        t = np.asarray(triangles)
        if self.uv_triangles.shape != t.shape:
            raise InputError(f"the UV atlas has {len(self.uv_triangles)} triangles, the mesh "
                             f"{len(t)}")
        owner = np.full(self.n_points, -1, np.int64)
        owner[self.uv_triangles.ravel()] = t.ravel()
        if np.any(owner[self.uv_triangles.ravel()] != t.ravel()):
            raise InputError("a texture point of the UV atlas is shared by two mesh vertices")
        if t.size and t.max() >= n_vertices:
            raise InputError(f"triangle index out of range [0, {n_vertices})")

    def restricted(self, kept_triangles: np.ndarray) -> UVAtlas:
        """Return the atlas of the triangles ``kept_triangles`` (bool (m,) or indices), compacted."""
        sub = self.uv_triangles[np.asarray(kept_triangles)]
        used, inverse = np.unique(sub.ravel(), return_inverse=True)
        return UVAtlas(self.uv[used], inverse.reshape(sub.shape))


def uv_vertices(atlas: UVAtlas, triangles: np.ndarray) -> np.ndarray:
    """Mesh vertex of every texture point, (t,) int64 (-1 for points no triangle uses)."""
    owner = np.full(atlas.n_points, -1, np.int64)
    owner[atlas.uv_triangles.ravel()] = np.asarray(triangles).ravel()
    return owner


def compute_uv_atlas(vertices: np.ndarray, triangles: np.ndarray, *,
                     resolution: int = ATLAS_RESOLUTION,
                     padding: int = ATLAS_PADDING) -> UVAtlas:
    """Cut the mesh into charts, flatten and pack them with xatlas (deterministic).

    Parameters
    ----------
    vertices : (n, 3) float array
        The mesh to unwrap (a model's reference or mean shape).
    triangles : (m, 3) int array
    resolution, padding : int
        Packing square in texels and empty texels between charts. xatlas may
        need a larger rectangle; the coordinates are scaled by one factor into
        the unit square, so texels stay square (some of the square stays empty).

    Returns
    -------
    UVAtlas
        Seconds: about 8 for a 40,000-triangle head on one core.
    """
    import xatlas

    v = np.ascontiguousarray(vertices, np.float32)
    t = np.ascontiguousarray(triangles, np.uint32)
    if v.ndim != 2 or v.shape[1] != 3 or t.ndim != 2 or t.shape[1] != 3 or not len(t):
        raise InputError(f"need vertices (n, 3) and triangles (m, 3), got {v.shape}, {t.shape}")
    atlas = xatlas.Atlas()
    atlas.add_mesh(v, t)
    pack = xatlas.PackOptions()
    pack.resolution = int(resolution)
    pack.padding = int(padding)
    pack.bilinear = True
    atlas.generate(xatlas.ChartOptions(), pack)
    mapping, uv_tri, uv = atlas[0]
    if not np.array_equal(mapping[uv_tri], t):
        raise InputError("xatlas changed the mesh's triangles (degenerate or duplicate faces?)")
    width, height = atlas.width, atlas.height
    side = max(width, height)
    uv = np.asarray(uv, np.float64) * (np.array([width, height], np.float64) / side)
    return UVAtlas(np.clip(uv, 0.0, 1.0), uv_tri.astype(np.int32))
