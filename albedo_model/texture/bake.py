"""Per-vertex values baked into a square texture image, and sampled back.

Baking a texture of ``size`` texels a side:

1. every texture point of the atlas is moved to the centre of the texel it
   falls in (at most half a texel); the baked mesh's UVs are these snapped
   points, so each vertex's value sits exactly on a texel centre and bilinear
   sampling at the vertex's UV returns it unchanged;
2. each texel centre inside a chart takes the linear interpolation of its
   triangle's corner values (the texel-to-triangle lookup is a ray cast
   through the flattened atlas with the Embree ray caster, watertight mode);
3. the texel of every texture point is set to that point's value;
4. empty texels take the value of the nearest filled texel (the gutter), so
   that bilinear filtering and mip-maps near a chart's border see no
   background.

Texture rows run top to bottom: row 0 is ``v = 1`` (OBJ/Blender convention).

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.uv_atlas` and
:mod:`albedo_model.render.raycast`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import ndimage

from albedo_model.errors import InputError
from albedo_model.render.raycast import RayCaster
from albedo_model.uv_atlas import UVAtlas, uv_vertices

__all__ = ["BakedTexture", "bake_vertex_values", "sample_texture", "snapped_atlas"]

#: Rays per Embree call (bounds the memory of large textures).
_RAYS_PER_BLOCK = 1 << 20


class BakedTexture(NamedTuple):
    """A texture image baked from per-vertex values.

    Attributes
    ----------
    image : (size, size, C) float32
        The values, row 0 at ``v = 1``; the gutter filled from the nearest chart texel.
    covered : (size, size) bool
        Texels inside a chart (False: gutter and empty space).
    atlas : UVAtlas
        The atlas with its points snapped to texel centres: the UVs to write with the texture.
    collisions : int
        Texels holding two or more texture points of different value (only the
        last is kept there; 0 when the atlas's charts are fine enough for ``size``).
    """

    image: np.ndarray
    covered: np.ndarray
    atlas: UVAtlas
    collisions: int


def _texel_index(uv: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of the texel each UV point falls in."""
    col = np.clip(np.floor(uv[:, 0] * size), 0, size - 1).astype(np.int64)
    row = np.clip(np.floor((1.0 - uv[:, 1]) * size), 0, size - 1).astype(np.int64)
    return row, col


def snapped_atlas(atlas: UVAtlas, size: int) -> UVAtlas:
    """Return ``atlas`` with every point moved to the centre of its texel at ``size``."""
    row, col = _texel_index(atlas.uv, size)
    uv = np.stack([(col + 0.5) / size, 1.0 - (row + 0.5) / size], axis=1)
    return UVAtlas(uv, atlas.uv_triangles)


def bake_vertex_values(atlas: UVAtlas, triangles: np.ndarray, values: np.ndarray,
                       size: int, *, threads: int | None = None) -> BakedTexture:
    """Bake per-vertex values into a ``size`` x ``size`` texture (see the module notes).

    Parameters
    ----------
    atlas : UVAtlas
        Texture coordinates of ``triangles``.
    triangles : (m, 3) int array
        The mesh the values belong to (the model's triangles).
    values : (n,) or (n, C) float array
        Per-vertex values (linear albedo, its std, ...).
    size : int
        Texels a side, at least 16.
    threads : {1, 2}, optional
        Ray-casting threads (default: the ray caster's).

    Returns
    -------
    BakedTexture
    """
    vals = np.asarray(values, np.float64)
    flat = vals.ndim == 1
    vals = vals[:, None] if flat else vals
    if vals.ndim != 2 or not np.all(np.isfinite(vals)):
        raise InputError(f"values must be finite, shape (n,) or (n, C), got {np.shape(values)}")
    if not isinstance(size, int | np.integer) or size < 16:
        raise InputError(f"texture size must be an integer >= 16, got {size!r}")
    tri = np.asarray(triangles)
    if tri.size and len(vals) <= tri.max():
        raise InputError(f"values have {len(vals)} rows; the triangles index {tri.max() + 1} "
                         "vertices")
    atlas.check_mesh(tri, len(vals))
    snapped = snapped_atlas(atlas, int(size))
    owner = uv_vertices(atlas, triangles)
    point_vals = vals[np.maximum(owner, 0)]

    # the flattened atlas in texel units (x right, y down), one ray per texel centre
    xy = np.stack([snapped.uv[:, 0] * size, (1.0 - snapped.uv[:, 1]) * size], axis=1)
    flat_mesh = np.column_stack([xy, np.zeros(len(xy))]).astype(np.float32)
    caster = RayCaster(flat_mesh, snapped.uv_triangles, threads=threads, robust=True,
                       update="rebuild")
    image = np.zeros((size * size, vals.shape[1]), np.float32)
    covered = np.zeros(size * size, bool)
    centres = np.arange(size, dtype=np.float32) + 0.5
    direction = np.array([[0.0, 0.0, -1.0]], np.float32)
    rows_per_block = max(1, _RAYS_PER_BLOCK // size)
    for r0 in range(0, size, rows_per_block):
        rows = centres[r0:r0 + rows_per_block]
        gy, gx = np.meshgrid(rows, centres, indexing="ij")
        origins = np.column_stack([gx.ravel(), gy.ravel(), np.ones(gx.size)]).astype(np.float32)
        hits = caster.cast(origins, direction, cull_backfaces=False)
        hit = hits.prim_id >= 0
        corner = snapped.uv_triangles[hits.prim_id[hit]]
        u, v = hits.bary[hit, 0:1].astype(np.float64), hits.bary[hit, 1:2].astype(np.float64)
        filled = ((1.0 - u - v) * point_vals[corner[:, 0]] + u * point_vals[corner[:, 1]]
                  + v * point_vals[corner[:, 2]])
        where = r0 * size + np.flatnonzero(hit)
        image[where] = filled
        covered[where] = True

    row, col = _texel_index(snapped.uv, size)
    used = owner >= 0
    texel = (row * size + col)[used]
    image[texel] = point_vals[used]
    covered[texel] = True
    order = np.argsort(texel, kind="stable")
    same = texel[order][1:] == texel[order][:-1]
    differs = np.any(point_vals[used][order][1:] != point_vals[used][order][:-1], axis=1)
    collisions = int(np.unique(texel[order][1:][same & differs]).size)

    image = image.reshape(size, size, -1)
    covered = covered.reshape(size, size)
    if covered.any() and not covered.all():
        nearest = ndimage.distance_transform_edt(~covered, return_distances=False,
                                                 return_indices=True)
        image = image[nearest[0], nearest[1]]
    return BakedTexture(image[..., 0] if flat else image, covered, snapped, collisions)


def sample_texture(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples of a texture at UV points (texel centres at ``(i + 0.5) / size``).

    Parameters
    ----------
    image : (H, W) or (H, W, C) float array
        Row 0 at ``v = 1``.
    uv : (k, 2) float array
        Points in [0, 1]^2; outside the outermost texel centres the edge texels hold.

    Returns
    -------
    (k,) or (k, C) float64 array
    """
    img = np.asarray(image, np.float64)
    pts = np.asarray(uv, np.float64)
    if img.ndim not in (2, 3) or pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(f"need an image (H, W[, C]) and uv (k, 2), got {img.shape}, {pts.shape}")
    h, w = img.shape[:2]
    coords = np.stack([(1.0 - pts[:, 1]) * h - 0.5, pts[:, 0] * w - 0.5])
    if img.ndim == 2:
        return ndimage.map_coordinates(img, coords, order=1, mode="nearest")
    return np.stack([ndimage.map_coordinates(img[..., c], coords, order=1, mode="nearest")
                     for c in range(img.shape[2])], axis=1)
