"""What a :class:`~albedo_model.render.Renderer` caches per scene, and its compiled stages.

:class:`RenderState` holds, for one set of scene parameters, the host instance,
the ray-cast buffers, and the device arrays of every stage down to the
per-pixel attributes the shader reads. The jitted stage functions here are
compiled once per :class:`~albedo_model.shading.Effects` value (and image
size); they take NumPy arguments where a value is small or used once, since
passing NumPy into a ``jit`` costs less than a separate ``device_put``.

This module imports only ``albedo_model`` modules (no Embree).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import numpy as np

from albedo_model.interpolation import (
    PixelAlbedo, PixelGeometry, PixelHits, interpolate_albedo, interpolate_geometry,
    needs_specular_albedo, needs_view, pixel_hits,
)
from albedo_model.normals_jax import vertex_normal_columns
from albedo_model.params import RenderParameter
from albedo_model.raycast import RayHits
from albedo_model.shading import Effects, Shaded, shade_pixels, unpack_shading_params

__all__ = ["RenderState", "Rendered", "normals_stage", "pixels_stage", "albedo_stage",
           "shade_stage", "fused_stage", "pixels_satisfy"]


class RenderState(NamedTuple):
    """Everything cached for one set of scene parameters (host and device arrays).

    Attributes
    ----------
    params : RenderParameter
    shape : (3n,) float32, host
        Shape + expression instance, interleaved (model frame, mm).
    albedo : (1, 3n) or (2, 3n) float32, host
        Diffuse albedo (row 0) and, when the renderer shades it, specular albedo (row 1).
    diffuse, specular : (3n,) float32 host views of the rows of ``albedo``
        (specular None when not rendered)
    vertices : (n, 3) float32 device array, model frame
    normals : three (n,) float32 device arrays, model frame (unit vertex normals)
    albedo_dev : device copy of ``albedo``
    hits : RayHits
        Host ray-cast buffers of every pixel (row-major).
    prim_id : (P,) int32, bary : (P, 2) float32
        The hits' buffers (host arrays; the device works on ``pixel_hits``).
    geometry_pending : bool
        True when the state's geometry lives in the renderer's spare scene
        (a proposal not yet accepted).
    pixel_hits : PixelHits
        Corner vertex ids and barycentric weights of every pixel, device.
    pixel_geometry : PixelGeometry
        Per-pixel world normals (and view directions), device.
    pixel_albedo : PixelAlbedo
        Per-pixel diffuse (and specular) albedo, device.
    effects : Effects
        The renderer's effect set for ``params``.
    shading : (PACKED_SIZE,) float32, host
        Packed shading parameters of ``params`` (:func:`albedo_model.shading.pack_shading_params`).
    updates : (int, int)
        Incremental block updates behind the shape and the albedo instances
        since they were last computed in full (see :mod:`albedo_model.instance_updates`).
    """

    params: RenderParameter
    shape: np.ndarray
    albedo: np.ndarray
    diffuse: np.ndarray
    specular: np.ndarray | None
    vertices: object
    normals: tuple
    albedo_dev: object
    hits: RayHits
    prim_id: np.ndarray
    bary: np.ndarray
    geometry_pending: bool
    pixel_hits: PixelHits
    pixel_geometry: PixelGeometry
    pixel_albedo: PixelAlbedo
    effects: Effects
    shading: np.ndarray
    updates: tuple[int, int] = (0, 0)


class Rendered(NamedTuple):
    """A rendered image.

    Attributes
    ----------
    image : (H, W, 3) float32, linear or gamma-encoded as requested
    mask : (H, W) bool, True on the face (alpha 1)
    state : RenderState, the buffers behind the image
    """

    image: np.ndarray
    mask: np.ndarray
    state: RenderState


def _split_albedo(effects: Effects, albedo_dev):
    """(diffuse, specular or None) as (n, 3) arrays from the (rows, 3n) device albedo."""
    diffuse = albedo_dev[0].reshape(-1, 3)
    specular = albedo_dev[1].reshape(-1, 3) if needs_specular_albedo(effects) else None
    return diffuse, specular


normals_stage = jax.jit(vertex_normal_columns)
normals_stage.__doc__ = "Jitted :func:`albedo_model.normals_jax.vertex_normal_columns`."


@functools.cache
def pixels_stage(effects: Effects):
    """Jitted ``f(triangles, normals, albedo_dev, prim_id, bary, ray_dirs, rotation)
    -> (PixelHits, PixelGeometry, PixelAlbedo)``, after a ray cast."""
    def pixels(triangles, normals, albedo_dev, prim_id, bary, ray_dirs, rotation):
        hits = pixel_hits(triangles, prim_id, bary)
        geometry = interpolate_geometry(effects, hits, normals, ray_dirs, rotation)
        diffuse, specular = _split_albedo(effects, albedo_dev)
        return hits, geometry, interpolate_albedo(effects, hits, diffuse, specular)
    return jax.jit(pixels)


@functools.cache
def albedo_stage(effects: Effects):
    """Jitted ``f(hits, albedo_dev) -> PixelAlbedo``, after an albedo change."""
    def albedo(hits, albedo_dev):
        return interpolate_albedo(effects, hits, *_split_albedo(effects, albedo_dev))
    return jax.jit(albedo)


@functools.cache
def shade_stage(effects: Effects):
    """Jitted ``f(geometry, albedo, packed, shadow) -> Shaded``."""
    def shade(geometry, albedo, packed, shadow) -> Shaded:
        return shade_pixels(effects, geometry, albedo, unpack_shading_params(packed), shadow)
    return jax.jit(shade)


def fused_stage(effects: Effects, fn):
    """Jitted ``f(geometry, albedo, packed, shadow, *args) -> fn(rgb, mask, *args)``."""
    def fused(geometry, albedo, packed, shadow, *args):
        out = shade_pixels(effects, geometry, albedo, unpack_shading_params(packed), shadow)
        return fn(out.rgb, out.mask, *args)
    return jax.jit(fused)


def pixels_satisfy(geometry: PixelGeometry, albedo: PixelAlbedo, effects: Effects) -> bool:
    """True when cached pixel attributes hold everything ``effects`` reads."""
    return ((geometry.view is not None or not needs_view(effects))
            and (albedo.specular is not None or not needs_specular_albedo(effects)))
