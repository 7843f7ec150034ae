"""What a :class:`~albedo_model.render.renderer.Renderer` caches per scene, and its compiled stages.

:class:`RenderState` holds, for one set of scene parameters, the host instance,
the ray-cast buffers, and the device arrays of every stage down to the
per-pixel attributes the shader reads. The jitted stage functions here are
compiled once per :class:`~albedo_model.shading.image_formation.Effects` value (and image
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

from albedo_model.shading.interpolation import (
    PixelGeometry, interpolate_albedo, interpolate_geometry, needs_specular_albedo, needs_view,
    normalise, pixel_hits,
)
from albedo_model.render.normals import vertex_normal_columns
from albedo_model.params import RenderParameter
from albedo_model.render.raycast import RayHits
from albedo_model.shading.image_formation import (
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

    Holds a :class:`~albedo_model.shading.interpolation.PixelHits`, ``PixelGeometry``,
    ``PixelAlbedo`` or :class:`~albedo_model.shading.image_formation.PixelLight`: reading an
    attribute (``.normal``, ``.diffuse``, ...) or :attr:`value` computes it
    once. :meth:`Renderer.compose <albedo_model.render.renderer.Renderer.compose>` instead
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
        Packed shading parameters of ``params`` (:func:`albedo_model.shading.image_formation.pack_shading_params`).
    updates : (int, int)
        Incremental block updates behind the shape and the albedo instances
        since they were last computed in full (see :mod:`albedo_model.render.instances`).
    pixels : (C,) int32 host array, or None
        The pixel set the per-pixel caches hold, as row-major pixel indices
        (sorted): every pixel whose ray hit, plus misses up to a bucketed size
        (so that compiled programs see few distinct shapes). None: every pixel.
        The caches' ``(P,)`` arrays above are then ``(C,)``; :meth:`full`
        expands one to the image, and the shading stages return whole images.
    pixels_dev : device copy of ``pixels`` (or None)
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
    pixels: np.ndarray | None = None
    pixels_dev: object = None

    def positions(self, indices: np.ndarray) -> np.ndarray:
        """Where pixels (row-major indices, all in the pixel set) sit in the caches' arrays."""
        idx = np.asarray(indices)
        return idx if self.pixels is None else np.searchsorted(self.pixels, idx)

    def full(self, values, fill=0.0) -> np.ndarray:
        """Per-pixel ``values`` of the state's pixel set as a whole image (host, row-major).

        Parameters
        ----------
        values : (C,) or (C, k) array (host or device)
            One value per entry of :attr:`pixels` (e.g. a channel of a pixel cache).
        fill : scalar
            Value of the pixels outside the set (all misses).

        Returns
        -------
        (H W,) or (H W, k) numpy array; ``values`` itself when the set is every pixel.
        """
        v = np.asarray(values)
        if self.pixels is None:
            return v
        w, h = self.params.image_size
        out = np.full((int(w) * int(h),) + v.shape[1:], fill, v.dtype)
        out[self.pixels] = v
        return out

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
normals_stage.__doc__ = "Jitted :func:`albedo_model.render.normals.vertex_normal_columns`."


def _at_pixels(values, pixels):
    """Per-pixel ``values`` (whole image) at the pixel set, or all of them when None."""
    return values if pixels is None else values[pixels]


@jax.jit
def hits_stage(triangles, prim_id, bary, pixels):
    """:func:`albedo_model.shading.interpolation.pixel_hits` of the whole-image ray-cast buffers
    ``prim_id`` (H W,) and ``bary`` (H W, 2) at the pixel set ``pixels`` (or all)."""
    return pixel_hits(triangles, _at_pixels(prim_id, pixels), _at_pixels(bary, pixels))


def _views(view, pixels):
    """Unit directions from the pixels' surface points towards the eye, world frame.

    ``view`` is ``((x, y), camera)`` as :meth:`Renderer._world_views` packs it: pixel
    coordinates of the image and (fx, fy, cx, cy, orthographic, R (3x3) world to
    eye). Eye rays are ``((x - cx) / fx, -(y - cy) / fy, -1)`` (orthographic:
    ``(0, 0, -1)``), a world direction is ``R^T`` of an eye direction, and the
    view direction is the reverse ray. Computed per pixel here rather than cached
    per camera: the sampler's camera proposals would miss any cache.
    """
    (xs, ys), cam = view
    if pixels is not None:
        xs, ys = xs[pixels], ys[pixels]
    perspective = cam[4] < 0.5
    a = jnp.where(perspective, (xs - cam[2]) / cam[0], 0.0)
    b = jnp.where(perspective, (cam[3] - ys) / cam[1], 0.0)
    r = cam[5:].reshape(3, 3)
    world = [a * r[0, c] + b * r[1, c] - r[2, c] for c in range(3)]
    return normalise(-world[0], -world[1], -world[2])


def _geometry(effects: Effects, hits, normals, rotation, view, pixels) -> PixelGeometry:
    no_view = effects._replace(specular=False, directional=False)
    geometry = interpolate_geometry(no_view, hits, normals, None, rotation)
    return geometry._replace(view=None if view is None else _views(view, pixels))


@functools.cache
def geometry_stage(effects: Effects):
    """Jitted ``f(hits, normals, rotation, view, pixels) -> PixelGeometry`` (``view`` as
    :func:`_views` reads it when :func:`~albedo_model.shading.interpolation.needs_view`, else
    None; ``pixels`` the state's device pixel set or None)."""
    return jax.jit(functools.partial(_geometry, effects))


def _expand(out: Shaded, pixels, n_pixels: int, background) -> Shaded:
    """Shader output of a pixel set scattered into whole-image arrays (background elsewhere)."""
    if pixels is None:
        return out

    def put(values, fill):
        full = jnp.full(n_pixels, fill, values.dtype)
        return full.at[pixels].set(values, indices_are_sorted=True, unique_indices=True)

    rgb = tuple(put(out.rgb[c], background[c]) for c in range(3))
    return Shaded(rgb=rgb, mask=put(out.mask, False))


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
    """The switches :func:`albedo_model.shading.image_formation.pixel_light` depends on (others at defaults)."""
    return effects._replace(color_transform=False, gamma=False, clamp=True)


@functools.cache
def light_stage(effects: Effects):
    """Jitted ``f(geometry, packed, shadow) -> PixelLight``."""
    def light(geometry, packed, shadow):
        return pixel_light(effects, geometry, unpack_shading_params(packed), shadow)
    return jax.jit(light)


@functools.cache
def combine_stage(effects: Effects, n_pixels: int):
    """Jitted ``f(light, albedo, mask, packed, pixels) -> Shaded`` of the whole image
    (``n_pixels`` = H W; ``pixels`` the state's device pixel set or None)."""
    def combine(light, albedo, mask, packed, pixels) -> Shaded:
        params = unpack_shading_params(packed)
        out = combine_pixels(effects, light, albedo, mask, params)
        return _expand(out, pixels, n_pixels, params.background)
    return jax.jit(combine)


def _apply(fn, out: Shaded, pixels, n_pixels: int, params, pixel_set: bool, args):
    """``fn`` of shaded pixels: on the pixel set, or on the whole image."""
    if pixel_set:
        return fn(out.rgb, out.mask, pixels, *args)
    out = _expand(out, pixels, n_pixels, params.background)
    return fn(out.rgb, out.mask, *args)


@functools.cache
def fused_stage(effects: Effects, fn, n_pixels: int, pixel_set: bool = False):
    """Jitted ``f(light, albedo, mask, packed, pixels, *args) -> fn(...)``.

    ``fn(rgb, mask, *args)`` of the whole image (``n_pixels`` = H W), or with
    ``pixel_set`` ``fn(rgb, mask, pixels, *args)`` of the state's pixel set.
    Cached per (effect set, ``fn``, image size, ``pixel_set``): every renderer
    composing the same function shares one compiled program per argument shape
    (no recompile per fit).
    """
    def fused(light, albedo, mask, packed, pixels, *args):
        params = unpack_shading_params(packed)
        out = combine_pixels(effects, light, albedo, mask, params)
        return _apply(fn, out, pixels, n_pixels, params, pixel_set, args)
    return jax.jit(fused)


@functools.cache
def image_stage(effects: Effects, fn, fused: frozenset, n_pixels: int, pixel_set: bool = False):
    """Jitted ``f(inputs, *args) -> fn(rgb, mask, *args)`` computing the pixel attributes
    named in ``fused`` (of "hits", "geometry", "albedo", "light") on the way.

    ``inputs`` is a dict: always ``packed`` (shading parameters), ``prim_id`` (of the whole
    image) and ``pixels`` (the pixel set, or None); ``triangles``, ``bary`` with "hits" fused,
    else ``hits`` when geometry or albedo are; ``normals``, ``rotation``, ``view`` with
    "geometry", else ``geometry`` when the light is fused; ``light_packed``, ``shadow`` with
    "light", else ``light``; ``albedo_dev`` with "albedo", else ``albedo``. One loop over the
    pixel set reads the per-vertex arrays and reduces into ``fn``'s result: ``fn(rgb, mask,
    pixels, *args)`` of the pixel set with ``pixel_set``, else ``fn(rgb, mask, *args)`` of the
    whole image (``n_pixels`` = H W; the shaded pixels are scattered into it). Cached per
    (effect set, ``fn``, ``fused``, image size, ``pixel_set``).
    """
    def image(inputs, *args):
        pixels = inputs["pixels"]
        prim_id = _at_pixels(inputs["prim_id"], pixels)
        if "hits" in fused:
            hits = pixel_hits(inputs["triangles"], prim_id, _at_pixels(inputs["bary"], pixels))
        else:
            hits = inputs.get("hits")
        if "geometry" in fused:
            geometry = _geometry(effects, hits, inputs["normals"], inputs["rotation"],
                                 inputs["view"], inputs["pixels"])
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
        params = unpack_shading_params(inputs["packed"])
        out = combine_pixels(effects, light, albedo, prim_id >= 0, params)
        return _apply(fn, out, pixels, n_pixels, params, pixel_set, args)
    return jax.jit(image)


def pixels_satisfy(geometry: Deferred, albedo: Deferred, effects: Effects) -> bool:
    """True when (deferred) pixel attributes hold everything ``effects`` reads."""
    return ((needs_view(geometry.effects) or not needs_view(effects))
            and (needs_specular_albedo(albedo.effects) or not needs_specular_albedo(effects)))
