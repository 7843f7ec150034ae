"""Image formation: per-pixel shading of ray-cast hits, specialised to the scene's effects.

Owns the shading maths of ``reference-sampler.md`` §2: SH-Lambert diffuse light,
AlbedoMM's specular term, scalismo's directional light (Lambert + Blinn-Phong)
with optional cast shadows, the colour transform, clamping, gamma 2.2 and the
background. Nothing here knows about Embree or the camera model: the inputs are
the ray caster's per-pixel ``prim_id``/``bary`` and the world-frame ray
directions of the pixels.

Layers, each usable on its own:

* :func:`pixel_light` turns per-pixel geometry
  (:class:`~albedo_model.shading.interpolation.PixelGeometry`) and the light into the
  per-pixel light transport (:class:`PixelLight`): what multiplies the diffuse
  and the specular albedo, plus what is added regardless of albedo.
* :func:`combine_pixels` multiplies in the per-pixel albedo
  (:class:`~albedo_model.shading.interpolation.PixelAlbedo`) and applies the colour
  transform, clamp, gamma and background. A renderer caches geometry, albedo
  and light transport, so a colour or albedo change is one cheap pass without
  gathers or light evaluation, and a light change two passes without gathers.
* :func:`shade_pixels` is ``combine_pixels(pixel_light(...))``.
* :func:`shade` (and :func:`shader_function`, :func:`build_shader`) does the
  interpolation too, from per-vertex arrays and hits: the composition
  ``shade_pixels(interpolate_geometry(...), interpolate_albedo(...))``.

Both are specialised per :class:`Effects` (a hashable set of switches): an
effect that is off is not traced, so it costs nothing (``tests`` check the
jaxpr). All per-pixel arrays are full-image sized (P = H W pixels, row-major)
with a hit mask, so the foreground size never changes a shape; the code works on
separate (P,) arrays per component (structure of arrays), which XLA-CPU runs
4-5x faster than (P, 3) code (``performance-notes.md`` §6).

Scene scalars travel as a :class:`ShadingParams` pytree
(:mod:`albedo_model.shading.scalars`, also packed into one vector).

This module imports only :mod:`albedo_model.params`, :mod:`albedo_model.sh`,
:mod:`albedo_model.shading.effects`, :mod:`albedo_model.shading.scalars` and
:mod:`albedo_model.shading.interpolation`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.shading.interpolation import (
    PixelAlbedo, PixelGeometry, interpolate_albedo, interpolate_geometry, normalise, pixel_hits,
)
from albedo_model.params import LUMA
from albedo_model.sh import LAMBERT_FACTORS, MAX_SH_COEFFICIENTS, SH_NORMALISATION
from albedo_model.shading.effects import Effects, effects_for, offset_count
from albedo_model.shading.scalars import (
    PACKED_SIZE, ShadingParams, pack_shading_params, shading_params, unpack_shading_params,
)

__all__ = [
    "Effects", "ShadingParams", "Shaded", "GAMMA", "PACKED_SIZE", "effects_for", "shading_params",
    "pack_shading_params", "unpack_shading_params", "PixelLight", "pixel_light",
    "combine_pixels", "shade_pixels", "pixel_shader_function",
    "shader_function", "build_shader", "shade", "encode_gamma", "to_hwc",
]

GAMMA = 2.2
_GAMMA_EPS = 1e-8
_POW_EPS = 1e-30


class Shaded(NamedTuple):
    """Shader output.

    Attributes
    ----------
    rgb : tuple of three (P,) float32 arrays (red, green, blue), row-major pixels;
        the background colour where ``mask`` is False. Linear unless ``Effects.gamma``.
    mask : (P,) bool, True where the ray hit the surface (alpha 1).
    """

    rgb: jax.Array
    mask: jax.Array


def encode_gamma(x: jax.Array) -> jax.Array:
    """Pure-power gamma ``x^(1/2.2)`` as ``exp(log(max(x, eps)) / 2.2)``; 0 for x <= eps.

    NaN-free for zero and negative inputs, with a zero (finite) gradient there.
    """
    safe = jnp.maximum(x, _GAMMA_EPS)
    return jnp.where(x > _GAMMA_EPS, jnp.exp(jnp.log(safe) * (1.0 / GAMMA)), 0.0)


def _safe_pow(x: jax.Array, e: jax.Array) -> jax.Array:
    """``max(x, 0)^e`` for e > 0 via exp/log; 0 (and zero gradient) where x <= 0."""
    safe = jnp.maximum(x, _POW_EPS)
    return jnp.where(x > _POW_EPS, jnp.exp(e * jnp.log(safe)), 0.0)


def _sh_lambert(weights: jax.Array, k: int, x, y, z) -> list:
    """``sum_i W_ic P_i(x, y, z)`` per channel, W = A N L folded, P the unnormalised basis."""
    terms = (None, lambda: y, lambda: z, lambda: x, lambda: x * y, lambda: y * z,
             lambda: 2.0 * z * z - x * x - y * y, lambda: x * z, lambda: x * x - y * y)
    polys = [terms[i]() for i in range(1, k)]
    out = []
    for c in range(3):
        acc = jnp.broadcast_to(weights[0, c], jnp.shape(x))
        for i, p in enumerate(polys, start=1):
            acc = acc + weights[i, c] * p
        out.append(acc)
    return out


def _luma(c):
    return LUMA[0] * c[0] + LUMA[1] * c[1] + LUMA[2] * c[2]


def _check(effects: Effects) -> None:
    if not 0 <= effects.sh_coefficients <= MAX_SH_COEFFICIENTS:
        raise ValueError(f"sh_coefficients must be in 0..9, got {effects.sh_coefficients}")
    if effects.shadows and not effects.directional:
        raise ValueError("shadows need a directional light")
    if effects.directional_specular_map and not effects.directional:
        raise ValueError("directional_specular_map needs a directional light")
    if effects.specular and effects.sh_coefficients == 0:
        raise ValueError("the AlbedoMM specular term needs SH light")


class PixelLight(NamedTuple):
    """Light transport of each pixel: everything of the image but the albedo.

    Before the colour transform, a pixel is ``diffuse * rho + specular * s +
    constant`` (per channel; rho, s the pixel's diffuse and specular albedo), so
    an albedo change re-combines cached :class:`PixelLight` without evaluating
    any light.

    Attributes
    ----------
    diffuse : three (P,) float32
        SH irradiance (plus the directional light's ambient and Lambert terms).
    specular : three (P,) float32, or None
        AlbedoMM's lobe times the SH light at the reflected direction (plus the
        directional Blinn-Phong term with ``directional_specular_map``); None
        when nothing multiplies the specular albedo.
    constant : three (P,) float32, or None
        The directional Blinn-Phong term without a specular map; else None.
    """

    diffuse: tuple
    specular: tuple | None
    constant: tuple | None


def pixel_light(effects: Effects, geometry: PixelGeometry, params: ShadingParams,
                shadow=None) -> PixelLight:
    """Per-pixel light transport (:class:`PixelLight`) of a scene; no albedo is read.

    Parameters
    ----------
    effects : Effects
        Static switches; an effect that is off is not traced.
    geometry : PixelGeometry
        From :func:`~albedo_model.shading.interpolation.interpolate_geometry` with the same
        effects (``view`` needed for specular or directional light).
    params : ShadingParams
        ``rotation`` is not read (the normals are already in the world frame).
    shadow : (P,) float32 or None
        Visibility of the directional light; only read with ``effects.shadows``.
    """
    _check(effects)
    k = effects.sh_coefficients
    nx, ny, nz = geometry.normal
    if k > 0:
        weights = jnp.asarray(LAMBERT_FACTORS[:k] * SH_NORMALISATION[:k], jnp.float32)[:, None]
        weights = weights * params.sh[:k]
        diffuse = _sh_lambert(weights, k, nx, ny, nz)
    else:
        diffuse = [jnp.zeros_like(nx)] * 3
    specular = constant = None
    if effects.specular or effects.directional:
        vx, vy, vz = geometry.view
    if effects.directional:
        lx, ly, lz = normalise(*(params.light_direction[i] for i in range(3)))
        ndl = jnp.maximum(nx * lx + ny * ly + nz * lz, 0.0)
        hx, hy, hz = normalise(vx + lx, vy + ly, vz + lz)
        blinn = _safe_pow(nx * hx + ny * hy + nz * hz, params.light_shininess)
        if effects.shadows:
            ndl = ndl * shadow
            blinn = blinn * shadow
        diffuse = [diffuse[c] + params.light_ambient[c] + params.light_diffuse[c] * ndl
                   for c in range(3)]
        spec_dir = [params.light_specular[c] * blinn for c in range(3)]
        if effects.directional_specular_map:
            specular = spec_dir
        else:
            constant = spec_dir
    if effects.specular:
        vn = vx * nx + vy * ny + vz * nz
        # AlbedoMM's "reflection" 2n - (v.n) v (not the mirror direction 2(v.n)n - v).
        rx, ry, rz = normalise(2.0 * nx - vn * vx, 2.0 * ny - vn * vy, 2.0 * nz - vn * vz)
        lobe = _safe_pow(vn, params.specular_exponent)
        spec_irr = _sh_lambert(weights, k, rx, ry, rz)
        lobe_light = [lobe * spec_irr[c] for c in range(3)]
        specular = lobe_light if specular is None else [
            specular[c] + lobe_light[c] for c in range(3)]
    return PixelLight(tuple(diffuse), None if specular is None else tuple(specular),
                      None if constant is None else tuple(constant))


def combine_pixels(effects: Effects, light: PixelLight, albedo: PixelAlbedo, mask,
                   params: ShadingParams) -> Shaded:
    """Form the image from light and albedo: colour transform, clamp, gamma, background.

    Parameters
    ----------
    effects : Effects
        Static; the same as for :func:`pixel_light`.
    light : PixelLight
    albedo : PixelAlbedo
    mask : (P,) bool
        Pixels on the surface (others get the background).
    params : ShadingParams
        Only the colour transform and background are read.
    """
    rho = albedo.diffuse
    total = [rho[c] * light.diffuse[c] for c in range(3)]
    if light.specular is not None:
        total = [total[c] + albedo.specular[c] * light.specular[c] for c in range(3)]
    if light.constant is not None:
        total = [total[c] + light.constant[c] for c in range(3)]
    if effects.color_transform:
        # ColorTransform.matrix applied channel by channel (fused into the pixel loop)
        kappa = params.color_contrast
        y = (1.0 - kappa) * _luma(total)
        n_offsets = offset_count(effects)
        total = [
            params.color_gain[c] * (kappa * total[c] + y) + n_offsets * params.color_offset[c]
            for c in range(3)
        ]
    if effects.clamp:
        total = [jnp.clip(c, 0.0, 1.0) for c in total]
    if effects.gamma:
        total = [encode_gamma(c) for c in total]
    # Three outputs, not one stacked (3, P) array: XLA-CPU turns a concatenate
    # into one branchy loop that recomputes the shading per channel (15x slower).
    rgb = tuple(jnp.where(mask, total[c], params.background[c]) for c in range(3))
    return Shaded(rgb=rgb, mask=mask)


def shade_pixels(effects: Effects, geometry: PixelGeometry, albedo: PixelAlbedo,
                 params: ShadingParams, shadow=None) -> Shaded:
    """Shade interpolated per-pixel attributes (the maths of :func:`shade`, without gathers).

    ``combine_pixels(pixel_light(geometry), albedo)``.

    Parameters
    ----------
    effects : Effects
        Static switches; an effect that is off is not traced.
    geometry : PixelGeometry
        From :func:`~albedo_model.shading.interpolation.interpolate_geometry` with the same
        effects (``view`` needed for specular or directional light).
    albedo : PixelAlbedo
        From :func:`~albedo_model.shading.interpolation.interpolate_albedo` with the same effects.
    params : ShadingParams
        ``rotation`` is not read (the normals are already in the world frame).
    shadow : (P,) float32 or None
        Visibility of the directional light; only read with ``effects.shadows``.

    Returns
    -------
    Shaded
    """
    light = pixel_light(effects, geometry, params, shadow)
    return combine_pixels(effects, light, albedo, geometry.mask, params)


def _shade(
    effects: Effects, triangles, normals, diffuse, specular, prim_id, bary, ray_dirs,
    params: ShadingParams, shadow,
) -> Shaded:
    hits = pixel_hits(triangles, prim_id, bary)
    geometry = interpolate_geometry(effects, hits, normals, ray_dirs, params.rotation)
    albedo = interpolate_albedo(effects, hits, diffuse, specular)
    return shade_pixels(effects, geometry, albedo, params, shadow)


def pixel_shader_function(effects: Effects) -> Callable[..., Shaded]:
    """Return the pure (un-jitted) :func:`shade_pixels` of one effect set, to use in a ``jit``.

    Returns ``f(geometry, albedo, params, shadow) -> Shaded``; validates ``effects``.
    """
    _check(effects)
    return functools.partial(shade_pixels, effects)


def shader_function(effects: Effects) -> Callable[..., Shaded]:
    """Return the pure (un-jitted) shader for one effect set, to compose in a larger ``jit``.

    Jitting shading together with the likelihood lets XLA fuse the per-pixel
    shading into the likelihood's reduction (no image is written out); with all
    effects on this halves the number of kernels. Arguments as :func:`shade`
    without ``effects``.
    """
    _check(effects)
    return functools.partial(_shade, effects)


@functools.cache
def build_shader(effects: Effects) -> Callable[..., Shaded]:
    """Return the jitted shader for one effect set (cached; one compile per input shape).

    Returns ``f(triangles, normals, diffuse, specular, prim_id, bary, ray_dirs,
    params, shadow) -> Shaded`` with the arguments of :func:`shade`.
    """
    return jax.jit(shader_function(effects))


def shade(
    effects: Effects,
    triangles: jax.Array,
    normals: jax.Array,
    diffuse: jax.Array,
    specular: jax.Array | None,
    prim_id: jax.Array,
    bary: jax.Array,
    ray_dirs: jax.Array | None,
    params: ShadingParams,
    shadow: jax.Array | None = None,
) -> Shaded:
    """Shade every pixel of an image from ray-cast hits.

    Parameters
    ----------
    effects : Effects
        Static switches; one compiled function per distinct value.
    triangles : (m, 3) int32
        Vertex indices of each triangle.
    normals : (n, 3) float32, object frame
        Unit vertex normals (interpolated, pose-rotated and renormalised per pixel).
    diffuse : (n, 3) float32
        Per-vertex diffuse albedo, linear RGB.
    specular : (n, 3) float32 or None
        Per-vertex specular albedo; only read with ``effects.specular``.
    prim_id : (P,) int32
        Hit triangle per pixel, -1 where the ray missed.
    bary : (P, 2) float32
        Embree's (u, v): the hit point is ``(1-u-v) a + u b + v c``. These are
        barycentrics of the 3-D point on the triangle, i.e. already perspective
        correct, so plain barycentric interpolation of vertex attributes with them
        is the perspective-correct interpolation a rasteriser reconstructs with 1/w.
        Ignored where ``prim_id == -1``.
    ray_dirs : (P, 3) float32, world frame, or None
        Direction of each pixel's camera ray (eye towards the surface; any positive
        length). Only read with ``effects.specular`` or ``effects.directional``.
    params : ShadingParams
    shadow : (P,) float32 or None
        Visibility of the directional light (1 lit, 0 shadowed); only read with
        ``effects.shadows``.

    Returns
    -------
    Shaded
        ``rgb`` three (P,) float32 arrays and ``mask`` (P,) bool.

    Notes
    -----
    * Diffuse: ``D = rho * sum_{i<k} A_i Y_i(n) L_i`` (+ directional
      ``rho (amb + diff max(n.l, 0) vis) + spec max(n.h, 0)^shininess vis``,
      ``h = normalise(v + l)``).
    * Specular (AlbedoMM): ``S = max(v.n, 0)^e s * sum_{i<k} A_i Y_i(r^) L_i`` with
      ``v = -normalise(ray_dir)`` and ``r = 2n - (v.n) v`` exactly as AlbedoMM writes
      it, which is not the mirror reflection ``2(v.n)n - v``; ``v.r = v.n``. For a
      pinhole camera with the eye at the world origin, ``v`` equals AlbedoMM's
      ``normalise(-p_world)`` without needing the hit depth (and it stays the
      direction to the eye for a non-identity view). With an orthographic camera
      ``v`` is the constant viewing direction, where AlbedoMM would still use
      ``-p_world``.
    * Colour transform ``T(c) = gain (kappa c + (1-kappa) Y(c)) + offset`` applied to D
      and S separately, as AlbedoMM does, so the offset counts twice with specular.
    * ``image = clamp01(T(D) + T(S))``, then optional gamma ``exp(log(max(x, eps))/2.2)``.
    * Compiles once per effect set and argument structure: keep passing the same
      shapes, and either always ``None`` or always an array for the optional inputs.
    """
    fn = build_shader(effects)
    return fn(triangles, normals, diffuse, specular, prim_id, bary, ray_dirs, params, shadow)


def to_hwc(rgb, height: int, width: int) -> np.ndarray:
    """Shader output (three (P,) arrays or a (3, P) array) as an (H, W, 3) NumPy image."""
    return np.stack([np.asarray(c).reshape(height, width) for c in rgb], axis=-1)
