"""Deliberately naive shading: the benchmark baseline and the tests' reference.

Same inputs and result as :func:`albedo_model.shading.image_formation.shade`, but written the
obvious way: (P, 3) arrays, an (P, 9) @ (9, 3) SH product, ``x ** (1/2.2)``, and
every effect always computed and multiplied by a 0/1 switch (one compiled
function for all effect sets). Do not use it for fitting.

This module imports only :mod:`albedo_model.params`, :mod:`albedo_model.sh` and
:mod:`albedo_model.shading.image_formation`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.params import LUMA
from albedo_model.sh import LAMBERT_FACTORS, MAX_SH_COEFFICIENTS, SH_NORMALISATION
from albedo_model.shading.image_formation import GAMMA, Effects, Shaded, ShadingParams

__all__ = ["shade_naive"]


def _unit(x: jax.Array) -> jax.Array:
    return x / jnp.maximum(jnp.linalg.norm(x, axis=-1, keepdims=True), 1e-15)


def _sh_matrix(d: jax.Array) -> jax.Array:
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    polys = jnp.stack([jnp.ones_like(x), y, z, x, x * y, y * z, 2 * z * z - x * x - y * y,
                       x * z, x * x - y * y], axis=-1)
    return polys * jnp.asarray(SH_NORMALISATION, jnp.float32)


def _transform(c, gain, contrast, offset, on):
    luma = c @ jnp.asarray(LUMA, jnp.float32)
    out = gain * (contrast * c + (1.0 - contrast) * luma[:, None]) + offset
    return on * out + (1.0 - on) * c


@jax.jit
def _shade_naive(sw, sh_mask, triangles, normals, diffuse, specular, prim_id, bary, ray_dirs,
                 params: ShadingParams, shadow) -> Shaded:
    hit = prim_id >= 0
    tri = triangles[jnp.maximum(prim_id, 0)]
    uv = jnp.where(hit[:, None], bary, 0.0)
    wts = jnp.concatenate([1.0 - uv.sum(-1, keepdims=True), uv], axis=-1)
    n = _unit(jnp.einsum("pk,pkc->pc", wts, normals[tri]) @ params.rotation.T)
    rho = jnp.einsum("pk,pkc->pc", wts, diffuse[tri])
    s_alb = jnp.einsum("pk,pkc->pc", wts, specular[tri])
    light = params.sh * (jnp.asarray(LAMBERT_FACTORS, jnp.float32) * sh_mask)[:, None]
    d = rho * (_sh_matrix(n) @ light)

    v = _unit(-ray_dirs)
    ldir = _unit(params.light_direction[None, :])
    vis = sw[2] * shadow + (1.0 - sw[2])
    ndl = jnp.maximum((n * ldir).sum(-1), 0.0)
    ndh = jnp.maximum((n * _unit(v + ldir)).sum(-1), 0.0)
    blinn = jnp.power(jnp.maximum(ndh, 1e-30), params.light_shininess) * (ndh > 1e-30)
    d = d + sw[1] * (rho * (params.light_ambient + params.light_diffuse * (ndl * vis)[:, None])
                     + params.light_specular * (blinn * vis)[:, None])

    vn = (v * n).sum(-1)
    r = _unit(2.0 * n - vn[:, None] * v)
    lobe = jnp.power(jnp.maximum(vn, 1e-30), params.specular_exponent) * (vn > 1e-30)
    s = sw[0] * lobe[:, None] * s_alb * (_sh_matrix(r) @ light)

    args = (params.color_gain, params.color_contrast, params.color_offset, sw[3])
    img = _transform(d, *args) + sw[0] * _transform(s, *args)
    img = sw[5] * jnp.clip(img, 0.0, 1.0) + (1.0 - sw[5]) * img
    gam = jnp.power(jnp.maximum(img, 1e-8), 1.0 / GAMMA) * (img > 1e-8)
    img = sw[4] * gam + (1.0 - sw[4]) * img
    rgb = jnp.where(hit[:, None], img, params.background[None, :])
    return Shaded(rgb=(rgb[:, 0], rgb[:, 1], rgb[:, 2]), mask=hit)


def shade_naive(
    effects: Effects, triangles, normals, diffuse, specular, prim_id, bary, ray_dirs,
    params: ShadingParams, shadow=None,
) -> Shaded:
    """Unspecialised (P, 3) shading; same arguments and result as :func:`shade`.

    Missing optional inputs (``specular``, ``ray_dirs``, ``shadow`` = None) are
    replaced by zeros / ones, since every effect is computed regardless.
    """
    n_vertices = normals.shape[0]
    n_pixels = prim_id.shape[0]
    if specular is None:
        specular = jnp.zeros((n_vertices, 3), jnp.float32)
    if ray_dirs is None:
        ray_dirs = jnp.broadcast_to(jnp.asarray([0.0, 0.0, -1.0], jnp.float32), (n_pixels, 3))
    if shadow is None:
        shadow = jnp.ones((n_pixels,), jnp.float32)
    sw = jnp.asarray([effects.specular, effects.directional, effects.shadows,
                      effects.color_transform, effects.gamma, effects.clamp], jnp.float32)
    sh_mask = jnp.asarray(np.arange(MAX_SH_COEFFICIENTS) < effects.sh_coefficients, jnp.float32)
    return _shade_naive(sw, sh_mask, triangles, normals, diffuse, specular, prim_id, bary,
                        ray_dirs, params, shadow)
