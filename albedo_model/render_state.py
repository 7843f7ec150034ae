"""What a :class:`~albedo_model.render.Renderer` caches per scene, and its compiled stages.

:class:`RenderState` holds, for one set of scene parameters, the host instance,
the ray-cast buffers, and the device arrays of every stage down to the
per-pixel attributes the shader reads. The jitted stage functions here are
compiled once per :class:`~albedo_model.shading.Effects` value (and image
size); they take NumPy arguments where a value is small or used once, since
passing NumPy into a ``jit`` costs less than a separate ``device_put``.

This module imports only ``albedo_model`` modules.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.interpolation import (
    PixelAlbedo, PixelGeometry, PixelHits, interpolate_albedo, interpolate_geometry,
    needs_specular_albedo, needs_view, pixel_hits,
)
from albedo_model.normals_jax import vertex_normal_columns
from albedo_model.params import RenderParameter
from albedo_model.raycast import RayHits
from albedo_model.shading import (
    Effects, PixelLight, Shaded, combine_pixels, pixel_light, unpack_shading_params,
)

__all__ = ["RenderState", "Rendered", "HostAlbedo", "normals_stage", "pixels_stage",
           "albedo_stage", "albedo_delta_stage", "light_stage", "combine_stage", "fused_stage",
           "pixels_satisfy"]


class HostAlbedo:
    """Host copy of a state's device albedo, made on first access (the hot path never needs it).

    Parameters
    ----------
    device : (rows, 3n) float32 device array
        Diffuse albedo (row 0) and, with two rows, specular albedo (row 1).
    host : (rows, 3n) float32 array, optional
        The same values on the host, when already at hand.
    """

    def __init__(self, device, host: np.ndarray | None = None):
        self.device = device
        self._host = None
        if host is not None:
            host = host.view()
            host.flags.writeable = False
            self._host = (host, host[0], host[1] if len(host) > 1 else None)

    @property
    def array(self) -> np.ndarray:
        """(rows, 3n) float32, read-only."""
        if self._host is None:
            host = np.array(self.device)
            host.flags.writeable = False
            self._host = (host, host[0], host[1] if len(host) > 1 else None)
        return self._host[0]

    @property
    def diffuse(self) -> np.ndarray:
        self.array
        return self._host[1]

    @property
    def specular(self) -> np.ndarray | None:
        self.array
        return self._host[2]


class RenderState(NamedTuple):
    """Everything cached for one set of scene parameters (host and device arrays).

    Attributes
    ----------
    params : RenderParameter
    shape : (3n,) float32, host
        Shape + expression instance, interleaved (model frame, mm).
    vertices : (n, 3) float32 device array, model frame
    normals : three (n,) float32 device arrays, model frame (unit vertex normals)
    albedo_dev : (1, 3n) or (2, 3n) float32 device array
        Diffuse albedo (row 0) and, when the renderer shades it, specular albedo
        (row 1), interleaved per vertex. Block updates happen on the device.
    host_albedo : HostAlbedo
        Its host copy, made when first read (properties ``albedo``, ``diffuse``,
        ``specular``: (rows, 3n) and (3n,) float32 host arrays, specular None
        when not rendered).
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
    pixel_light : PixelLight
        Per-pixel light transport (everything of the image but the albedo), device.
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
    vertices: object
    normals: tuple
    albedo_dev: object
    host_albedo: HostAlbedo
    hits: RayHits
    prim_id: np.ndarray
    bary: np.ndarray
    geometry_pending: bool
    pixel_hits: PixelHits
    pixel_geometry: PixelGeometry
    pixel_albedo: PixelAlbedo
    pixel_light: PixelLight
    effects: Effects
    shading: np.ndarray
    updates: tuple[int, int] = (0, 0)

    @property
    def albedo(self) -> np.ndarray:
        """(rows, 3n) float32 host copy of ``albedo_dev``."""
        return self.host_albedo.array

    @property
    def diffuse(self) -> np.ndarray:
        """(3n,) float32 host diffuse albedo instance."""
        return self.host_albedo.diffuse

    @property
    def specular(self) -> np.ndarray | None:
        """(3n,) float32 host specular albedo instance, None when not rendered."""
        return self.host_albedo.specular


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
    """Jitted ``f(triangles, normals, albedo_dev, prim_id, bary, rotation)
    -> (PixelHits, PixelGeometry, PixelAlbedo)``, after a ray cast.

    The geometry's ``view`` is left None: view directions depend on the camera
    only, and the renderer caches them per camera.
    """
    no_view = effects._replace(specular=False, directional=False)

    def pixels(triangles, normals, albedo_dev, prim_id, bary, rotation):
        hits = pixel_hits(triangles, prim_id, bary)
        geometry = interpolate_geometry(no_view, hits, normals, None, rotation)
        diffuse, specular = _split_albedo(effects, albedo_dev)
        return hits, geometry, interpolate_albedo(effects, hits, diffuse, specular)
    return jax.jit(pixels)


@functools.cache
def albedo_stage(effects: Effects):
    """Jitted ``f(hits, albedo_dev) -> PixelAlbedo``, after an albedo change."""
    def albedo(hits, albedo_dev):
        return interpolate_albedo(effects, hits, *_split_albedo(effects, albedo_dev))
    return jax.jit(albedo)


@jax.jit
def albedo_delta_stage(albedo_dev, basis_t, idx, delta):
    """``albedo_dev`` plus ``sum_j delta_j basis_t[idx_j]`` in its leading ``basis_t.shape[1]``
    entries (flattened), in one fused pass over the changed rows of the transposed basis:
    about as fast as the same product in NumPy, and no host-to-device copy.

    Kept out of the interpolation's ``jit``: there XLA fuses the row sum into every
    gather of the albedo and recomputes it per pixel (ten times slower).
    """
    flat = albedo_dev.reshape(-1)
    width = basis_t.shape[1]
    head = flat[:width]
    for j in range(idx.shape[0]):
        head = head + delta[j] * jax.lax.dynamic_index_in_dim(basis_t, idx[j], keepdims=False)
    flat = head if width == flat.shape[0] else jnp.concatenate([head, flat[width:]])
    return flat.reshape(albedo_dev.shape)


@functools.cache
def light_stage(effects: Effects):
    """Jitted ``f(geometry, packed, shadow) -> PixelLight``."""
    def light(geometry, packed, shadow):
        return pixel_light(effects, geometry, unpack_shading_params(packed), shadow)
    return jax.jit(light)


@functools.cache
def combine_stage(effects: Effects):
    """Jitted ``f(light, albedo, mask, packed) -> Shaded``."""
    def combine(light, albedo, mask, packed) -> Shaded:
        return combine_pixels(effects, light, albedo, mask, unpack_shading_params(packed))
    return jax.jit(combine)


def fused_stage(effects: Effects, fn):
    """Jitted ``f(light, albedo, mask, packed, *args) -> fn(rgb, mask, *args)``."""
    def fused(light, albedo, mask, packed, *args):
        out = combine_pixels(effects, light, albedo, mask, unpack_shading_params(packed))
        return fn(out.rgb, out.mask, *args)
    return jax.jit(fused)


def pixels_satisfy(geometry: PixelGeometry, albedo: PixelAlbedo, effects: Effects) -> bool:
    """True when cached pixel attributes hold everything ``effects`` reads."""
    return ((geometry.view is not None or not needs_view(effects))
            and (albedo.specular is not None or not needs_specular_albedo(effects)))
