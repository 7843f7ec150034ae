"""What a :class:`~albedo_model.render.Renderer` caches per scene, and its compiled stages.

:class:`RenderState` holds, for one set of scene parameters, the host instance,
the ray-cast buffers, and the device arrays of every stage down to the
per-pixel attributes the shader reads. The jitted stage functions here are
compiled once per :class:`~albedo_model.shading.Effects` value (and image
size); they take NumPy arguments where a value is small or used once, since
passing NumPy into a ``jit`` costs less than a separate ``device_put``.

The per-pixel attributes are :class:`Deferred`: computed when first read.
XLA-CPU compiles a program with many per-pixel outputs into about one loop
per output (35 for the pixel attributes of a ray cast), while what feeds a
single reduction fuses into a few loops; :func:`image_stage` therefore
evaluates what a proposal changed inside the likelihood's own program and
writes nothing out (250x250, specular on: pixel attributes, light and
likelihood of a ray cast 5.1 ms as stages, 3.0 ms fused; an albedo step's
gathers and likelihood 3.2 ms and 0.8 ms).

This module imports only ``albedo_model`` modules.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.interpolation import (
    PixelGeometry, interpolate_albedo, interpolate_geometry, needs_specular_albedo, needs_view,
    pixel_hits,
)
from albedo_model.normals_jax import vertex_normal_columns
from albedo_model.params import RenderParameter
from albedo_model.raycast import RayHits
from albedo_model.shading import (
    Effects, Shaded, combine_pixels, pixel_light, unpack_shading_params,
)

__all__ = ["RenderState", "Rendered", "HostAlbedo", "Deferred", "normals_stage", "hits_stage",
           "geometry_stage", "albedo_stage", "albedo_delta_stage", "light_stage", "light_effects",
           "combine_stage", "fused_stage", "image_stage", "pixels_satisfy"]


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


class Deferred:
    """One per-pixel cache of a render state, computed when first needed.

    Holds a :class:`~albedo_model.interpolation.PixelHits`, ``PixelGeometry``,
    ``PixelAlbedo`` or :class:`~albedo_model.shading.PixelLight`: reading an
    attribute (``.normal``, ``.diffuse``, ...) or :attr:`value` computes it
    once. :meth:`Renderer.compose <albedo_model.render.Renderer.compose>` instead
    evaluates a *fresh* value (created by the step being evaluated, not computed,
    not used before) inside the likelihood's program (:func:`image_stage`) and
    marks it used: a rejected proposal never writes its pixel attributes out,
    and an accepted one computes them when a later step reads them.

    Parameters
    ----------
    stage : callable
        ``stage(**inputs) -> value``, with Deferred inputs replaced by their values.
    inputs : dict
        Arrays (and Deferred values) the value is computed from; the fused
        programs read these instead of the value.
    effects : Effects
        The effect set the value is computed for.
    """

    __slots__ = ("_stage", "_value", "inputs", "effects", "fresh")

    def __init__(self, stage, inputs: dict, effects: Effects):
        self._stage, self._value = stage, None
        self.inputs, self.effects, self.fresh = inputs, effects, True

    @property
    def computed(self) -> bool:
        return self._value is not None

    @property
    def value(self):
        """The computed NamedTuple of device arrays."""
        if self._value is None:
            args = {k: v.value if isinstance(v, Deferred) else v for k, v in self.inputs.items()}
            self._value = self._stage(**args)
            self.fresh = False
        return self._value

    def __getattr__(self, name: str):
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.value, name)


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
    pixel_hits : Deferred PixelHits
        Corner vertex ids and barycentric weights of every pixel, device.
    pixel_geometry : Deferred PixelGeometry
        Per-pixel world normals (and view directions), device.
    pixel_albedo : Deferred PixelAlbedo
        Per-pixel diffuse (and specular) albedo, device.
    pixel_light : Deferred PixelLight
        Per-pixel light transport (everything of the image but the albedo), device.
        The four are computed when first read (:class:`Deferred`).
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
    pixel_hits: Deferred
    pixel_geometry: Deferred
    pixel_albedo: Deferred
    pixel_light: Deferred
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


hits_stage = jax.jit(pixel_hits)
hits_stage.__doc__ = "Jitted :func:`albedo_model.interpolation.pixel_hits`."


def _geometry(effects: Effects, hits, normals, rotation, view) -> PixelGeometry:
    # view directions depend on the camera only: the renderer caches them per camera
    no_view = effects._replace(specular=False, directional=False)
    return interpolate_geometry(no_view, hits, normals, None, rotation)._replace(view=view)


@functools.cache
def geometry_stage(effects: Effects):
    """Jitted ``f(hits, normals, rotation, view) -> PixelGeometry`` (``view`` three (P,)
    arrays when :func:`~albedo_model.interpolation.needs_view`, else None)."""
    return jax.jit(functools.partial(_geometry, effects))


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


def light_effects(effects: Effects) -> Effects:
    """The switches :func:`albedo_model.shading.pixel_light` depends on (others at defaults)."""
    return effects._replace(color_transform=False, gamma=False, clamp=True)


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


@functools.cache
def fused_stage(effects: Effects, fn):
    """Jitted ``f(light, albedo, mask, packed, *args) -> fn(rgb, mask, *args)``.

    Cached per (effect set, ``fn``): every renderer composing the same function
    shares one compiled program per argument shape (no recompile per fit).
    """
    def fused(light, albedo, mask, packed, *args):
        out = combine_pixels(effects, light, albedo, mask, unpack_shading_params(packed))
        return fn(out.rgb, out.mask, *args)
    return jax.jit(fused)


@functools.cache
def image_stage(effects: Effects, fn, fused: frozenset):
    """Jitted ``f(inputs, *args) -> fn(rgb, mask, *args)`` computing the pixel attributes
    named in ``fused`` (of "hits", "geometry", "albedo", "light") on the way.

    ``inputs`` is a dict: always ``packed`` (shading parameters) and ``prim_id``;
    ``triangles``, ``bary`` with "hits" fused, else ``hits`` when geometry or albedo
    are; ``normals``, ``rotation``, ``view`` with "geometry", else ``geometry`` when
    the light is fused; ``light_packed``, ``shadow`` with "light", else ``light``;
    ``albedo_dev`` with "albedo", else ``albedo``. One loop over the pixels reads
    the per-vertex arrays and reduces into ``fn``'s result. Cached per (effect set,
    ``fn``, ``fused``).
    """
    def image(inputs, *args):
        if "hits" in fused:
            hits = pixel_hits(inputs["triangles"], inputs["prim_id"], inputs["bary"])
        else:
            hits = inputs.get("hits")
        if "geometry" in fused:
            geometry = _geometry(effects, hits, inputs["normals"], inputs["rotation"],
                                 inputs["view"])
        else:
            geometry = inputs.get("geometry")
        if "light" in fused:
            light = pixel_light(light_effects(effects), geometry,
                                unpack_shading_params(inputs["light_packed"]), inputs["shadow"])
        else:
            light = inputs["light"]
        if "albedo" in fused:
            albedo = interpolate_albedo(effects, hits,
                                        *_split_albedo(effects, inputs["albedo_dev"]))
        else:
            albedo = inputs["albedo"]
        out = combine_pixels(effects, light, albedo, inputs["prim_id"] >= 0,
                             unpack_shading_params(inputs["packed"]))
        return fn(out.rgb, out.mask, *args)
    return jax.jit(image)


def pixels_satisfy(geometry: Deferred, albedo: Deferred, effects: Effects) -> bool:
    """True when (deferred) pixel attributes hold everything ``effects`` reads."""
    return ((needs_view(geometry.effects) or not needs_view(effects))
            and (needs_specular_albedo(albedo.effects) or not needs_specular_albedo(effects)))
