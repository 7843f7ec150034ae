"""Per-pixel attributes of ray-cast hits: interpolated normals, view directions, albedo.

The first half of image formation, split from the shading maths
(:mod:`albedo_model.shading.image_formation`) so that a renderer can cache its results: the
pixel geometry (:class:`PixelGeometry`) changes only when the ray cast or the
vertex normals do, the pixel albedo (:class:`PixelAlbedo`) only when the ray
cast or the albedo instance does. A light or colour proposal then shades the
cached pixels without a single gather.

Every per-pixel quantity is a separate (P,) array (structure of arrays,
``performance-notes.md`` §6), full-image sized with a hit mask. Per-vertex
inputs may be (n, 3) arrays or triples of (n,) arrays.

This module imports only :mod:`albedo_model.shading.effects`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from albedo_model.shading.effects import Effects

__all__ = [
    "PixelHits", "PixelGeometry", "PixelAlbedo", "pixel_hits", "interpolate_geometry",
    "interpolate_albedo", "needs_view", "needs_specular_albedo", "normalise",
]

_NORM_EPS = 1e-30


class PixelHits(NamedTuple):
    """Where each pixel's ray hit the mesh, ready for interpolation (device arrays).

    Attributes
    ----------
    mask : (P,) bool
        True where the ray hit the surface.
    corner : three (P,) int32
        Vertex ids of the hit triangle's corners (those of triangle 0 on misses).
    weight : three (P,) float32
        Barycentric weights ``(1-u-v, u, v)`` of the corners ((1, 0, 0) on misses).
    """

    mask: jax.Array
    corner: tuple
    weight: tuple


class PixelGeometry(NamedTuple):
    """Geometry seen by each pixel (device arrays, P = H W, row-major).

    Attributes
    ----------
    mask : (P,) bool
        True where the pixel's ray hit the surface.
    normal : three (P,) float32
        Unit surface normal, world frame (interpolated vertex normals, rotated
        by the pose and renormalised). Meaningless where ``mask`` is False.
    view : three (P,) float32, or None
        Unit direction from the surface towards the eye, world frame; only with
        :func:`needs_view` effects.
    """

    mask: jax.Array
    normal: tuple
    view: tuple | None


class PixelAlbedo(NamedTuple):
    """Albedo seen by each pixel (device arrays).

    Attributes
    ----------
    diffuse : three (P,) float32
        Interpolated diffuse albedo, linear RGB.
    specular : three (P,) float32, or None
        Interpolated specular albedo; only with :func:`needs_specular_albedo` effects.
    """

    diffuse: tuple
    specular: tuple | None


def needs_view(effects: Effects) -> bool:
    """Return whether shading reads the view direction (specular or directional light)."""
    return bool(effects.specular or effects.directional)


def needs_specular_albedo(effects: Effects) -> bool:
    """Return whether shading reads the specular albedo."""
    return bool(effects.specular or effects.directional_specular_map)


def normalise(x, y, z):
    """Componentwise unit vector (zero stays finite: scaled by ``rsqrt(max(|v|^2, eps))``)."""
    inv = jax.lax.rsqrt(jnp.maximum(x * x + y * y + z * z, _NORM_EPS))
    return x * inv, y * inv, z * inv


def pixel_hits(triangles, prim_id, bary) -> PixelHits:
    """Corner vertex ids and barycentric weights of every pixel's hit.

    Parameters
    ----------
    triangles : (m, 3) int32
    prim_id : (P,) int32
        Hit triangle per pixel, -1 for a miss.
    bary : (P, 2) float32
        Embree's (u, v): the hit point is ``(1-u-v) a + u b + v c``. These are
        barycentrics of the 3-D hit point, i.e. already perspective correct.

    Returns
    -------
    PixelHits
    """
    hit = prim_id >= 0
    pid = jnp.maximum(prim_id, 0)
    corner = tuple(triangles[:, j][pid] for j in range(3))
    u = jnp.where(hit, bary[:, 0], 0.0)
    v = jnp.where(hit, bary[:, 1], 0.0)
    return PixelHits(hit, corner, (1.0 - u - v, u, v))


def _columns(attr) -> tuple:
    if isinstance(attr, (tuple, list)):
        return tuple(attr)
    return tuple(attr[:, c] for c in range(3))


def _interp(attr, hits: PixelHits) -> tuple:
    """Three (P,) arrays: barycentric interpolation of a per-vertex 3-vector."""
    (w, u, v), (c0, c1, c2) = hits.weight, hits.corner
    return tuple(w * a[c0] + u * a[c1] + v * a[c2] for a in _columns(attr))


def interpolate_geometry(effects: Effects, hits: PixelHits, normals, ray_dirs,
                         rotation) -> PixelGeometry:
    """Per-pixel world normals (and view directions) from ray-cast hits.

    Parameters
    ----------
    effects : Effects
        Static; the view direction is computed only when :func:`needs_view`.
    hits : PixelHits
    normals : (n, 3) float32 or three (n,) float32, object (model) frame
        Unit vertex normals.
    ray_dirs : (P, 3) float32, world frame, or None
        Camera ray per pixel (eye towards the surface, any positive length);
        only read when :func:`needs_view`.
    rotation : (3, 3) float32
        World-from-object rotation of the pose.

    Returns
    -------
    PixelGeometry
    """
    nox, noy, noz = _interp(normals, hits)
    r = rotation
    normal = normalise(*(r[i, 0] * nox + r[i, 1] * noy + r[i, 2] * noz for i in range(3)))
    view = None
    if needs_view(effects):
        view = normalise(-ray_dirs[:, 0], -ray_dirs[:, 1], -ray_dirs[:, 2])
    return PixelGeometry(hits.mask, normal, view)


def interpolate_albedo(effects: Effects, hits: PixelHits, diffuse, specular) -> PixelAlbedo:
    """Per-pixel diffuse (and specular) albedo from ray-cast hits.

    Parameters
    ----------
    effects : Effects
        Static; the specular albedo is read only when :func:`needs_specular_albedo`.
    hits : PixelHits
    diffuse, specular : (n, 3) float32 or three (n,) float32, linear RGB
        (``specular`` may be None when not needed)

    Returns
    -------
    PixelAlbedo
    """
    spec = _interp(specular, hits) if needs_specular_albedo(effects) else None
    return PixelAlbedo(_interp(diffuse, hits), spec)
