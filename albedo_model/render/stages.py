"""The compiled stages of a render: normals, pixel hits, pixel geometry and albedo, light, image.

Each jitted stage is compiled once per :class:`~albedo_model.shading.effects.Effects`
value (and image size); they take NumPy arguments where a value is small or
used once, since passing NumPy into a ``jit`` costs less than a separate
``device_put``. :func:`image_stage` fuses the per-pixel attributes a step
changed into the likelihood's own program (250x250, specular on: pixel
attributes, light and likelihood of a ray cast 5.1 ms as stages, 3.0 ms fused;
an albedo step's gathers and likelihood 3.2 ms and 0.8 ms).

This module imports :mod:`albedo_model.render.normals`, :mod:`albedo_model.render.state`
and :mod:`albedo_model.shading` (effects, image_formation, interpolation).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from albedo_model.render.normals import vertex_normal_columns
from albedo_model.render.state import Deferred
from albedo_model.shading.effects import Effects
from albedo_model.shading.image_formation import (
    Shaded, combine_pixels, pixel_light, unpack_shading_params,
)
from albedo_model.shading.interpolation import (
    PixelGeometry, interpolate_albedo, interpolate_geometry, needs_specular_albedo, needs_view,
    normalise, pixel_hits,
)

__all__ = ["normals_stage", "hits_stage", "geometry_stage", "albedo_stage", "albedo_delta_stage",
           "light_stage", "light_effects", "combine_stage", "fused_stage", "image_stage",
           "pixels_satisfy"]


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
    """Gather the hit triangles' corners and weights at the pixel set ``pixels`` (or all).

    :func:`albedo_model.shading.interpolation.pixel_hits` of the whole-image ray-cast
    buffers ``prim_id`` (H W,) and ``bary`` (H W, 2).
    """
    return pixel_hits(triangles, _at_pixels(prim_id, pixels), _at_pixels(bary, pixels))


def _views(view, pixels):
    """Compute unit directions from the pixels' surface points towards the eye, world frame.

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
    """Build the jitted ``f(hits, normals, rotation, view, pixels) -> PixelGeometry``.

    ``view`` is as :func:`_views` reads it when
    :func:`~albedo_model.shading.interpolation.needs_view`, else None; ``pixels``
    the state's device pixel set or None.
    """
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
    """Add ``sum_j delta_j basis_t[idx_j]`` to the device albedo, on the device.

    The sum goes into the leading ``basis_t.shape[1]`` entries of ``albedo_dev``
    (flattened), in one fused pass over the changed rows of the transposed basis:
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
    """Reduce ``effects`` to the switches the light stage depends on (others at defaults).

    Those are the switches :func:`albedo_model.shading.image_formation.pixel_light`
    reads; effect sets that agree on them share the cached light and its program.
    """
    return effects._replace(color_transform=False, gamma=False, clamp=True)


@functools.cache
def light_stage(effects: Effects):
    """Jitted ``f(geometry, packed, shadow) -> PixelLight``."""
    def light(geometry, packed, shadow):
        return pixel_light(effects, geometry, unpack_shading_params(packed), shadow)
    return jax.jit(light)


@functools.cache
def combine_stage(effects: Effects, n_pixels: int):
    """Build the jitted ``f(light, albedo, mask, packed, pixels) -> Shaded`` of the whole image.

    ``n_pixels`` = H W; ``pixels`` is the state's device pixel set or None.
    """
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
    """Build the jitted ``f(inputs, *args) -> fn(rgb, mask, *args)`` with fused attributes.

    It computes the pixel attributes named in ``fused`` (of "hits", "geometry",
    "albedo", "light") on the way.

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
    """Tell whether the (deferred) pixel attributes hold everything ``effects`` reads."""
    return ((needs_view(geometry.effects) or not needs_view(effects))
            and (needs_specular_albedo(albedo.effects) or not needs_specular_albedo(effects)))
