"""Image formation: per-pixel shading of ray-cast hits, specialised to the scene's effects.

Owns the shading maths of ``reference-sampler.md`` §2: SH-Lambert diffuse light,
AlbedoMM's specular term, scalismo's directional light (Lambert + Blinn-Phong)
with optional cast shadows, the colour transform, clamping, gamma 2.2 and the
background. Nothing here knows about Embree or the camera model: the inputs are
the ray caster's per-pixel ``prim_id``/``bary`` and the world-frame ray
directions of the pixels.

The shader is compiled once per :class:`Effects` (a hashable set of switches):
an effect that is off is not traced, so it costs nothing (``tests`` check the
jaxpr). All per-pixel arrays are full-image sized (P = H W pixels, row-major)
with a hit mask, so the foreground size never changes a shape; the code works on
separate (P,) arrays per component (structure of arrays), which XLA-CPU runs
4-5x faster than (P, 3) code (``performance-notes.md`` §6).

This module imports only :mod:`albedo_model.params` and :mod:`albedo_model.sh`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.params import RenderParameter
from albedo_model.sh import LAMBERT_FACTORS, MAX_SH_COEFFICIENTS, SH_NORMALISATION

__all__ = [
    "Effects", "ShadingParams", "Shaded", "GAMMA", "effects_for", "shading_params",
    "shader_function", "build_shader", "shade", "encode_gamma", "to_hwc",
]

GAMMA = 2.2
_GAMMA_EPS = 1e-8
_POW_EPS = 1e-30
_NORM_EPS = 1e-30
_LUMA = (0.3, 0.59, 0.11)


class Effects(NamedTuple):
    """Which effects a scene's image formation computes (hashable; one compiled shader each).

    Attributes
    ----------
    sh_coefficients : int
        Number of SH coefficients used, 0..9 (``min(K, 9)``); 0 turns SH light off.
    specular : bool
        AlbedoMM specular term (needs per-vertex specular albedo).
    directional : bool
        scalismo's directional light (Lambert + Blinn-Phong), added to the SH light.
    shadows : bool
        Multiply the directional diffuse and specular terms by a per-pixel
        visibility (needs ``directional``).
    color_transform : bool
        Apply gain / contrast / offset (off = identity).
    gamma : bool
        Encode the clamped image with ``x^(1/2.2)`` (off = linear output, as fitted).
    clamp : bool
        Clamp ``D + S`` to [0, 1] (AlbedoMM does; the plain scalismo renderer does not).
    directional_specular_map : bool
        Scale the directional light's Blinn-Phong term by the per-vertex specular
        albedo (the paper's appendix renders; needs ``directional``).
    """

    sh_coefficients: int = 9
    specular: bool = False
    directional: bool = False
    shadows: bool = False
    color_transform: bool = False
    gamma: bool = False
    clamp: bool = True
    directional_specular_map: bool = False


class ShadingParams(NamedTuple):
    """Scene scalars of the shading, as a pytree of float32 arrays (traced, never static).

    Attributes
    ----------
    rotation : (3, 3) world-from-object rotation of the pose (normals are rotated
        and renormalised, so a positive scale factor is harmless).
    sh : (9, 3) radiance map in scalismo's order, zero-padded to 9 rows (world frame).
    specular_exponent : () AlbedoMM exponent e.
    light_direction : (3,) direction towards the directional light (world frame).
    light_ambient, light_diffuse, light_specular : (3,) RGB.
    light_shininess : () Blinn-Phong exponent.
    color_gain : (3,), color_contrast : (), color_offset : (3,)
    background : (3,) RGB written where no surface is hit (output space).
    """

    rotation: jax.Array
    sh: jax.Array
    specular_exponent: jax.Array
    light_direction: jax.Array
    light_ambient: jax.Array
    light_diffuse: jax.Array
    light_specular: jax.Array
    light_shininess: jax.Array
    color_gain: jax.Array
    color_contrast: jax.Array
    color_offset: jax.Array
    background: jax.Array


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


def effects_for(
    params: RenderParameter,
    has_specular: bool,
    *,
    specular: bool = True,
    shadows: bool = False,
    gamma: bool = False,
    clamp: bool = True,
    directional_specular_map: bool = False,
) -> Effects:
    """The effect set a scene needs.

    Specular is on iff the model has a specular part, the caller asks for it and
    the SH light is non-empty (AlbedoMM's specular reuses the SH light);
    directional iff ``params.directional_light.enabled``; shadows only with a
    directional light; colour transform iff it is not the identity;
    ``directional_specular_map`` only with a directional light and a specular part.

    Notes
    -----
    scalismo uses the directional light only when the SH light is empty; here both
    are summed when both are set (the default directional light is off).
    """
    k = min(int(params.environment_map.coefficients.shape[0]), MAX_SH_COEFFICIENTS)
    directional = bool(params.directional_light.enabled)
    return Effects(
        sh_coefficients=k,
        specular=bool(has_specular and specular and k > 0),
        directional=directional,
        shadows=bool(shadows and directional),
        color_transform=not params.color_transform.is_identity,
        gamma=bool(gamma),
        clamp=bool(clamp),
        directional_specular_map=bool(directional_specular_map and directional and has_specular),
    )


def shading_params(
    params: RenderParameter, rotation: np.ndarray, *, background=(0.0, 0.0, 0.0)
) -> ShadingParams:
    """Device-resident :class:`ShadingParams` from a scene.

    Parameters
    ----------
    params : RenderParameter
    rotation : (3, 3) float array
        World-from-object rotation of ``params.pose`` (``Rz(roll) Ry(yaw) Rx(pitch)``).
    background : (3,) float
        Output colour of pixels without a hit.
    """
    sh = np.zeros((MAX_SH_COEFFICIENTS, 3), np.float32)
    coeffs = np.asarray(params.environment_map.coefficients, np.float64)
    if coeffs.ndim != 2 or coeffs.shape[1] != 3:
        raise ValueError(f"SH coefficients must have shape (K, 3), got {coeffs.shape}")
    k = min(coeffs.shape[0], MAX_SH_COEFFICIENTS)
    sh[:k] = coeffs[:k]
    dl = params.directional_light
    ct = params.color_transform

    def f32(x):
        return jnp.asarray(np.asarray(x, np.float32))

    return ShadingParams(
        rotation=f32(np.asarray(rotation).reshape(3, 3)), sh=f32(sh),
        specular_exponent=f32(params.specular_exponent),
        light_direction=f32(dl.direction), light_ambient=f32(dl.ambient),
        light_diffuse=f32(dl.diffuse), light_specular=f32(dl.specular),
        light_shininess=f32(dl.shininess), color_gain=f32(ct.gain),
        color_contrast=f32(ct.contrast), color_offset=f32(ct.offset), background=f32(background),
    )


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


def _normalise(x, y, z):
    inv = jax.lax.rsqrt(jnp.maximum(x * x + y * y + z * z, _NORM_EPS))
    return x * inv, y * inv, z * inv


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
    return _LUMA[0] * c[0] + _LUMA[1] * c[1] + _LUMA[2] * c[2]


def _shade(
    effects: Effects, triangles, normals, diffuse, specular, prim_id, bary, ray_dirs,
    params: ShadingParams, shadow,
) -> Shaded:
    k = effects.sh_coefficients
    hit = prim_id >= 0
    pid = jnp.maximum(prim_id, 0)
    corner = [triangles[:, j][pid] for j in range(3)]
    u = jnp.where(hit, bary[:, 0], 0.0)
    v = jnp.where(hit, bary[:, 1], 0.0)
    w = 1.0 - u - v

    def interp(attr):  # (n, 3) per vertex -> three (P,) arrays
        cols = [attr[:, c] for c in range(3)]
        return [w * a[corner[0]] + u * a[corner[1]] + v * a[corner[2]] for a in cols]

    nox, noy, noz = interp(normals)
    r = params.rotation
    nx, ny, nz = _normalise(*(r[i, 0] * nox + r[i, 1] * noy + r[i, 2] * noz for i in range(3)))
    rho = interp(diffuse)

    if k > 0:
        weights = jnp.asarray(LAMBERT_FACTORS[:k] * SH_NORMALISATION[:k], jnp.float32)[:, None]
        weights = weights * params.sh[:k]
        irr = _sh_lambert(weights, k, nx, ny, nz)
        dif = [rho[c] * irr[c] for c in range(3)]
    else:
        dif = [jnp.zeros_like(u)] * 3

    if effects.specular or effects.directional:
        vx, vy, vz = _normalise(-ray_dirs[:, 0], -ray_dirs[:, 1], -ray_dirs[:, 2])

    if effects.directional:
        lx, ly, lz = _normalise(*(params.light_direction[i] for i in range(3)))
        ndl = jnp.maximum(nx * lx + ny * ly + nz * lz, 0.0)
        hx, hy, hz = _normalise(vx + lx, vy + ly, vz + lz)
        blinn = _safe_pow(nx * hx + ny * hy + nz * hz, params.light_shininess)
        if effects.shadows:
            ndl = ndl * shadow
            blinn = blinn * shadow
        spec_dir = [params.light_specular[c] * blinn for c in range(3)]
        if effects.directional_specular_map:
            s_map = interp(specular)
            spec_dir = [spec_dir[c] * s_map[c] for c in range(3)]
        dif = [
            dif[c] + rho[c] * (params.light_ambient[c] + params.light_diffuse[c] * ndl) + spec_dir[c]
            for c in range(3)
        ]

    total = dif
    if effects.specular:
        vn = vx * nx + vy * ny + vz * nz
        # AlbedoMM's "reflection" 2n - (v.n) v (not the mirror direction 2(v.n)n - v).
        rx, ry, rz = _normalise(2.0 * nx - vn * vx, 2.0 * ny - vn * vy, 2.0 * nz - vn * vz)
        lobe = _safe_pow(vn, params.specular_exponent)
        spec_irr = _sh_lambert(weights, k, rx, ry, rz)
        s_alb = interp(specular)
        total = [dif[c] + lobe * s_alb[c] * spec_irr[c] for c in range(3)]

    if effects.color_transform:
        # The transform is affine, so T(D) + T(S) = T_linear(D + S) + 2 offset:
        # AlbedoMM applies it to D and S separately and the offset counts twice.
        kappa = params.color_contrast
        y = (1.0 - kappa) * _luma(total)
        n_offsets = 2.0 if effects.specular else 1.0
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
    rgb = tuple(jnp.where(hit, total[c], params.background[c]) for c in range(3))
    return Shaded(rgb=rgb, mask=hit)


def shader_function(effects: Effects) -> Callable[..., Shaded]:
    """The pure (un-jitted) shader for one effect set, to compose inside a larger ``jit``.

    Jitting shading together with the likelihood lets XLA fuse the per-pixel
    shading into the likelihood's reduction (no image is written out); with all
    effects on this halves the number of kernels. Arguments as :func:`shade`
    without ``effects``.
    """
    if not 0 <= effects.sh_coefficients <= MAX_SH_COEFFICIENTS:
        raise ValueError(f"sh_coefficients must be in 0..9, got {effects.sh_coefficients}")
    if effects.shadows and not effects.directional:
        raise ValueError("shadows need a directional light")
    if effects.directional_specular_map and not effects.directional:
        raise ValueError("directional_specular_map needs a directional light")
    if effects.specular and effects.sh_coefficients == 0:
        raise ValueError("the AlbedoMM specular term needs SH light")
    return functools.partial(_shade, effects)


@functools.lru_cache(maxsize=None)
def build_shader(effects: Effects) -> Callable[..., Shaded]:
    """The jitted shader for one effect set (cached; one compile per input shape).

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
