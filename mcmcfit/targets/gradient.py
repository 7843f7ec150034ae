"""The gradient of the log posterior in the continuous geometry blocks, for gradient-informed moves.

:func:`posterior_gradient` returns ``grad(params) -> (log_density, gradient)``
for a :class:`~mcmcfit.targets.face.FaceTarget`, with the gradient in the flat
layout of :func:`proposals.gradient.vector_layout` (shape, expression, then
yaw, pitch, roll (rad), t_x, t_y, t_z (mm), then the focal length). It is the
sum of

* the **prior** (:mod:`mcmcfit.targets.priors`: analytic derivatives of its
  Gaussian and log-normal factors, the distance factor through ``t_z``);
* the **landmark** log likelihood (:class:`~mcmcfit.targets.landmarks.LandmarkTarget`:
  its Gaussian terms projected in JAX, with each landmark's visibility as the
  target decides it at ``params``; another factor, e.g. a face box, by central
  finite differences of its ``log_lik``);
* the **image** log likelihood as the target's
  :class:`~mcmcfit.targets.image.ImageLikelihood` defines it (kind, sigma,
  temperature), differentiated through
  :func:`albedo_model.render.differentiable.pixel_colours` over the face pixels of a ray
  cast at ``params``. Only the foreground part is differentiated: the set of face
  pixels (the silhouette) and the triangle each one sees are held at that ray
  cast, so the background term ``-bg(I_p)`` of a pixel and the per-pixel
  normaliser are constants (a pixel entering or leaving the face is a jump, not a
  derivative).

The value returned is the log posterior ``log p + l_lm + l_img`` at ``params``
(the image term from the same ray cast, in float64 on the host).

The ray cast is this object's own: one private Embree scene of the model
(updated with the instance at ``params``, computed from all coefficients), its
own ray buffers and pixel-set capacity, so the sampler's renderer and its
double-buffered scenes are never touched, and the result is a function of
``params`` alone (what :class:`proposals.gradient.MALA` needs to be exact; up to
which of two triangles Embree reports for a ray exactly on their shared edge).
The target's factors (its image likelihood's sigma and temperature included)
are read at every call. Cost at 250x250 on the default face model: about 20 ms
(6 ms of it the ray cast), against 5-10 ms for a render step of the sampler.

This module imports :mod:`albedo_model` (camera, errors, params, render.differentiable,
render.pixel_cast), :mod:`proposals.gradient`, and :mod:`mcmcfit.targets` (face,
landmarks, likelihoods).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.camera import eye_from_world, principal_point_px
from albedo_model.errors import InputError
from albedo_model.params import Block, RenderParameter
from albedo_model.render.differentiable import (
    DifferentiableModel,
    GeometryParams,
    build_value_and_grad,
    euler_rotation_jax,
    fixed_hits,
    geometry_params,
)
from albedo_model.render.pixel_cast import SceneCaster
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.landmarks import LandmarkTarget
from mcmcfit.targets.likelihoods import (
    finish_collective,
    finish_independent,
    finish_trimmed,
)
from proposals.gradient import (
    GRADIENT_BLOCKS,
    GradFn,
    block_vector,
    vector_layout,
    with_block_vector,
)

__all__ = ["GradFn", "GradientParts", "PosteriorGradient", "posterior_gradient",
           "prior_gradient"]

_FD_STEP = 1e-5  # relative step of the finite-difference fallback (landmark factors)


class GradientParts(NamedTuple):
    """Each factor's value and gradient (GeometryParams pytrees of float64 arrays)."""

    log_prior: float
    log_lik_lm: float
    log_lik_img: float
    prior: GeometryParams
    landmarks: GeometryParams
    image: GeometryParams
    face_pixels: int


def _zeros_like(geo: GeometryParams) -> GeometryParams:
    return GeometryParams(*(np.zeros(np.shape(a)) for a in geo))


def _add(a: GeometryParams, b: GeometryParams) -> GeometryParams:
    return GeometryParams(*(np.asarray(x, np.float64) + np.asarray(y, np.float64)
                            for x, y in zip(a, b)))


def _flat(geo: GeometryParams, params: RenderParameter, blocks: Block) -> np.ndarray:
    parts = {Block.SHAPE: geo.shape, Block.EXPRESSION: geo.expression,
             Block.POSE: np.concatenate([geo.angles, geo.translation]),
             Block.CAMERA: np.reshape(geo.focal_length, 1)}
    runs = vector_layout(params, blocks)
    return np.concatenate([np.asarray(parts[b], np.float64).reshape(-1) for b, _ in runs])


def _lognormal_dlog(x: float, median: float, log_sigma: float) -> float:
    """``d/dx`` of the log-normal log density (:func:`~mcmcfit.targets.priors.lognormal_logpdf`)."""
    if not x > 0.0:
        return math.nan
    return -(math.log(x) - math.log(median)) / (log_sigma * log_sigma * x) - 1.0 / x


def prior_gradient(target: FaceTarget, params: RenderParameter) -> GeometryParams:
    """Gradient of :class:`~mcmcfit.targets.priors.LogPrior` in the geometry parameters."""
    c = target.prior.config
    p = params
    tx, ty, tz = p.pose.translation
    d = float(p.view.translation[2]) - float(tz)  # distance = view_z - t_z
    return GeometryParams(
        -np.asarray(p.momo.shape, np.float64), -np.asarray(p.momo.expression, np.float64),
        np.array([-p.pose.yaw / c.yaw_sigma ** 2, -p.pose.pitch / c.pitch_sigma ** 2,
                  -p.pose.roll / c.roll_sigma ** 2]),
        np.array([-tx / c.translation_sigma ** 2, -ty / c.translation_sigma ** 2,
                  -_lognormal_dlog(d, c.distance_median, c.distance_log_sigma)]),
        np.asarray(_lognormal_dlog(p.camera.focal_length, c.focal_median, c.focal_log_sigma)))


def _landmark_value(geometry: GeometryParams, inputs: tuple, orthographic: bool):
    """Sum over visible landmarks of ``-d^2 / (2 sigma^2)`` (JAX; constants left out)."""
    mean, sb, eb, observed, inv_var, camera, view_r, view_t, near, scaling = inputs
    k = mean.shape[0]
    pts = mean + (sb @ geometry.shape + eb @ geometry.expression).reshape(k, 3)
    yaw, pitch, roll = geometry.angles[0], geometry.angles[1], geometry.angles[2]
    rot = view_r @ euler_rotation_jax(roll, yaw, pitch) * scaling
    eye = pts @ rot.T + (view_r @ geometry.translation + view_t)
    sx, sy, w, h, cx, cy = (camera[i] for i in range(6))
    fx, fy = w * geometry.focal_length / sx, h * geometry.focal_length / sy
    depth = jnp.full_like(eye[:, 2], near) if orthographic else -eye[:, 2]
    u = cx + fx * eye[:, 0] / depth
    v = cy - fy * eye[:, 1] / depth
    d2 = (u - observed[:, 0]) ** 2 + (v - observed[:, 1]) ** 2
    return -0.5 * jnp.sum(d2 * inv_var)


_landmark_grad = functools.cache(
    lambda orthographic: jax.jit(jax.grad(functools.partial(
        lambda o, g, i: _landmark_value(g, i, o), orthographic))))


def _image_terms(kind: str):
    """Return ``readout(rgb, mask, pixels, target_rgb, bg, sigma, extra) -> (value, terms)``.

    ``terms`` are the per-pixel ``||I - R||^2`` (collective) or ``-||I - R||^2 / (2 sigma^2)
    - bg(I)`` (independent, trimmed), from which the host sums the value in float64.
    """
    def readout(rgb, mask, pixels, target_rgb, bg, sigma, extra):
        d2 = sum((c - t.reshape(-1)[pixels]) ** 2 for c, t in zip(rgb, target_rgb))
        if kind == "collective":
            n = jnp.maximum(jnp.sum(mask), 1).astype(d2.dtype)
            m = jnp.sum(jnp.where(mask, d2, 0.0)) / (sigma * sigma * n)
            z = (m - 1.0) / jnp.sqrt(extra / n)
            return -0.5 * z * z, d2
        val = -d2 * (0.5 / (sigma * sigma)) - bg.reshape(-1)[pixels]
        kept = mask
        if kind == "trimmed":  # the best ``extra`` pixels, chosen here (not differentiated)
            ranked = jnp.sort(jax.lax.stop_gradient(jnp.where(mask, val, -jnp.inf)))
            threshold = ranked[ranked.shape[0] - jnp.maximum(extra.astype(jnp.int32), 1)]
            kept = mask & (val >= threshold)
        return jnp.sum(jnp.where(kept, val, 0.0)), val
    return readout


#: One read-out function per likelihood kind (compiled programs are cached on it).
_READOUTS = {kind: _image_terms(kind) for kind in ("independent", "collective", "trimmed")}


class PosteriorGradient:
    """``grad(params) -> (log_density, gradient)`` of a face posterior (see the module notes).

    Parameters
    ----------
    target : FaceTarget
    blocks : Block
        Part of :data:`proposals.gradient.GRADIENT_BLOCKS`: the flat vector's blocks.
    threads : int
        Ray-casting threads of the private scene.
    """

    def __init__(self, target: FaceTarget, blocks: Block, *, threads: int = 1):
        self.target = target
        self.blocks = Block(blocks)
        if not self.blocks or self.blocks & ~GRADIENT_BLOCKS:
            raise InputError(f"gradient blocks must be a non-empty part of SHAPE | EXPRESSION "
                             f"| POSE | CAMERA, got {self.blocks!r}")
        r = target.renderer
        self.model = r.model
        self._diff = DifferentiableModel(r.model, specular=r.specular, background=r.background,
                                         directional_specular_map=r.directional_specular_map)
        self._caster = SceneCaster(r.model, threads=threads)
        self._capacity: dict[int, int] = {}
        self._landmark_inputs: dict = {}

    # -- the ray cast ----------------------------------------------------------
    def ray_cast(self, params: RenderParameter) -> np.ndarray:
        """Return the triangle per pixel (H W,) int32 (-1: miss) of a private cast at ``params``."""
        return self._caster.cast(params)[0]

    # -- factors -----------------------------------------------------------------
    def _image(self, params: RenderParameter,
               geo: GeometryParams) -> tuple[float, GeometryParams, int]:
        lik = self.target.image_likelihood
        if lik is None:
            return 0.0, _zeros_like(geo), 0
        effects = self.target.renderer.effects(params)
        w, h = int(params.image_size.width), int(params.image_size.height)
        prim = self.ray_cast(params)
        hits, self._capacity[w * h] = fixed_hits(prim, w, h, self._capacity.get(w * h))
        mask = prim[hits.pixels] >= 0
        n = int(mask.sum())
        if n == 0:
            return -math.inf, _zeros_like(geo), 0
        if lik.kind == "collective":
            sigma, extra = math.sqrt(3.0) * lik.sigma, lik.relative_variance
        else:
            sigma, extra = lik.sigma, math.floor(lik.trim_fraction * n)
        fn = build_value_and_grad(effects, bool(params.camera.orthographic), _READOUTS[lik.kind])
        (_, terms), grad = fn(geo, self._diff.scene(params), hits, jnp.asarray(hits.pixels),
                              lik.target.arrays.rgb, lik.target.arrays.bg, jnp.float32(sigma),
                              jnp.float32(extra))
        terms = np.asarray(terms, np.float64)[mask]
        if lik.kind == "collective":
            value = finish_collective([terms.sum()], [n], sigma, lik.relative_variance)
        elif lik.kind == "independent":
            value = finish_independent([terms.sum()], [n], lik.sigma)
        else:
            value = finish_trimmed(terms, np.ones(n, bool), lik.sigma, lik.trim_fraction)
        t = float(lik.temperature)
        return value / t, GeometryParams(*(np.asarray(g, np.float64) / t for g in grad)), n

    def _landmark_arrays(self, factor: LandmarkTarget, params: RenderParameter):
        key = (len(params.momo.shape), len(params.momo.expression))
        if key not in self._landmark_inputs:
            m = self.model
            vid = m.landmark_vertices
            rows = np.concatenate([np.arange(3 * vid[n], 3 * vid[n] + 3) for n in factor.names])
            mean = m.shape.mean[rows].astype(np.float64)
            eb = np.zeros((rows.size, key[1]))
            if m.expression is not None:
                mean = mean + m.expression.mean[rows]
                eb = m.expression.scaled_basis[rows, :key[1]]
            sigma = np.broadcast_to(np.asarray(factor.sigma, np.float64), (len(factor.names),))
            self._landmark_inputs[key] = (mean.reshape(-1, 3), m.shape.scaled_basis[rows, :key[0]],
                                          eb, factor.observed, 1.0 / sigma ** 2)
        return self._landmark_inputs[key]

    def _landmarks(self, params: RenderParameter,
                   geo: GeometryParams) -> tuple[float, GeometryParams]:
        factor = self.target.landmarks
        value = self.target.log_lik_landmarks(params)
        if factor is None:
            return value, _zeros_like(geo)
        if not isinstance(factor, LandmarkTarget):
            return value, self._finite_difference(params, geo)
        _, visible = factor.project(params)
        mean, sb, eb, observed, inv_var = self._landmark_arrays(factor, params)
        p = params
        cx, cy = principal_point_px(p.camera, p.image_size)
        rv, tv = eye_from_world(p.view)
        camera = np.array([p.camera.sensor_size[0], p.camera.sensor_size[1], p.image_size.width,
                           p.image_size.height, cx, cy])
        inputs = (mean, sb, eb, observed, np.where(visible, inv_var, 0.0), camera, rv, tv,
                  float(p.camera.near), float(p.pose.scaling))
        with jax.enable_x64(True):
            g64 = geometry_params(params, np.float64)
            grad = _landmark_grad(bool(p.camera.orthographic))(g64, inputs)
            grad = GeometryParams(*(np.asarray(g, np.float64) for g in grad))
        return value, grad

    def _finite_difference(self, params: RenderParameter, geo: GeometryParams) -> GeometryParams:
        """Central differences of the landmark factor's ``log_lik`` in every geometry entry."""
        blocks = Block.SHAPE | Block.EXPRESSION | Block.POSE | Block.CAMERA
        x = block_vector(params, blocks)
        g = np.zeros_like(x)
        for i in range(x.shape[0]):
            h = _FD_STEP * max(1.0, abs(x[i]))
            up, down = x.copy(), x.copy()
            up[i] += h
            down[i] -= h
            f = self.target.log_lik_landmarks
            g[i] = (f(with_block_vector(params, blocks, up))
                    - f(with_block_vector(params, blocks, down))) / (2 * h)
        ks, ke = len(params.momo.shape), len(params.momo.expression)
        return GeometryParams(g[:ks], g[ks:ks + ke], g[ks + ke:ks + ke + 3],
                              g[ks + ke + 3:ks + ke + 6], g[ks + ke + 6])

    # -- public API ---------------------------------------------------------------
    def parts(self, params: RenderParameter) -> GradientParts:
        """Each factor's value and gradient at ``params`` (GeometryParams, float64)."""
        geo = geometry_params(params)
        img_value, img_grad, n = self._image(params, geo)
        lm_value, lm_grad = self._landmarks(params, geo)
        return GradientParts(float(self.target.log_prior(params)), float(lm_value), img_value,
                             prior_gradient(self.target, params), lm_grad, img_grad, n)

    def __call__(self, params: RenderParameter) -> tuple[float, np.ndarray]:
        """Return the log posterior at ``params`` and its gradient (flat layout of ``blocks``)."""
        parts = self.parts(params)
        total = _add(_add(parts.prior, parts.landmarks), parts.image)
        value = parts.log_prior + parts.log_lik_lm + parts.log_lik_img
        return float(value), _flat(total, params, self.blocks)


def posterior_gradient(target: FaceTarget, blocks: Block, *, threads: int = 1) -> GradFn:
    """Return ``grad(params) -> (log_density, gradient)`` of the posterior of ``target``.

    Parameters
    ----------
    target : FaceTarget
        Its renderer's model and shading settings, image likelihood, landmark
        factor and prior define the posterior.
    blocks : Block
        The blocks of the flat vector (:func:`proposals.gradient.vector_layout`), a
        part of SHAPE | EXPRESSION | POSE | CAMERA.
    threads : int
        Ray-casting threads of the gradient's private scene.

    Returns
    -------
    PosteriorGradient
        Callable as ``GradFn``; ``parts(params)`` gives the factors separately.

    Raises
    ------
    InputError
        Blocks outside the gradient blocks.
    """
    return PosteriorGradient(target, blocks, threads=threads)

