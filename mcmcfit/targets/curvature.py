"""The log posterior's gradient and Gauss-Newton precision in the scene vector: for optimisation and Laplace.

Over a fixed pixel region (:class:`~mcmcfit.targets.image.ImageLikelihood`
with ``region``) the image log likelihood is a sum of squared residuals,
``-sum_p ||I_p - R_p(x)||^2 / (2 sigma^2 T)``, a smooth function of the scene
vector ``x`` (:class:`~albedo_model.scene_vector.SceneLayout`). Its gradient is
``J^T r / (sigma^2 T)`` and its Gauss-Newton precision ``J^T J / (sigma^2 T)``
(with a robust foreground each pixel's rows weighted by its probability of
being the face) with ``J`` the pixel Jacobian (:class:`~albedo_model.render.jacobian.PixelJacobian`,
at the triangles a ray cast at ``x`` sees). The landmark likelihood is a sum
of squared pixel distances too (Gauss-Newton through a JAX projection of the
landmark points, visibility held); the prior's gradient and precision are
analytic. :meth:`PosteriorCurvature.at` returns all three summed:

* ``gradient`` of ``log p(x | data)`` (D,),
* ``precision`` (D, D): Gauss-Newton (positive semi-definite) for the
  likelihoods, the exact negative Hessian for the prior.

:meth:`proposals.laplace.coordinates.SamplingCoordinates.to_coordinates` carries them to
the sampling coordinates. The numbers serve proposals and an optimiser, never
the acceptance test, which always uses the exact ray-cast posterior.

This module imports :mod:`albedo_model` (camera, errors, params, scene_vector,
render.differentiable, render.jacobian, render.pixel_cast) and :mod:`mcmcfit.targets`
(face, landmarks, priors, robust_foreground).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.camera import eye_from_world
from albedo_model.errors import InputError
from albedo_model.params import RenderParameter
from albedo_model.render.differentiable import euler_rotation_jax
from albedo_model.render.jacobian import PixelJacobian
from albedo_model.render.pixel_cast import SceneCaster, hits_at
from albedo_model.scene_vector import SceneLayout
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.landmarks import LandmarkTarget
from mcmcfit.targets.priors import PriorConfig, directional_prior
from mcmcfit.targets.robust_foreground import face_weights, missed_value, readout_weights

__all__ = ["Curvature", "PosteriorCurvature", "SceneCaster", "coordinate_gradient", "hits_at",
           "prior_curvature"]


class Curvature(NamedTuple):
    """A log density's gradient and precision at one point (float64).

    Attributes
    ----------
    gradient : (D,)
    precision : (D, D) symmetric
    pixels : int
        Region pixels the image part was computed on.
    exact_gradient : (D,) or None
        The gradient of the terms whose precision is exact (the prior), for
        :meth:`~proposals.laplace.coordinates.SamplingCoordinates.to_coordinates`.
    """

    gradient: np.ndarray
    precision: np.ndarray
    pixels: int = 0
    exact_gradient: np.ndarray | None = None


def _lognormal_terms(x: float, median: float, log_sigma: float) -> tuple[float, float]:
    """Gradient and negative second derivative of the log-normal log density at x > 0."""
    s2 = log_sigma * log_sigma
    z = math.log(x) - math.log(median)
    return -z / (s2 * x) - 1.0 / x, (1.0 - z - s2) / (s2 * x * x)


def prior_curvature(params: RenderParameter, layout: SceneLayout,
                    config: PriorConfig) -> tuple[np.ndarray, np.ndarray]:
    """Gradient and (diagonal) precision of :class:`~mcmcfit.targets.priors.LogPrior` in ``x``."""
    from mcmcfit.targets.priors import LogPrior

    c, p = config, params
    sl = layout.slices()
    x = layout.vector(p)
    g, h = np.zeros(layout.size), np.zeros(layout.size)

    def normal(index, mean, sd):
        g[index] = -(x[index] - mean) / (sd * sd)
        h[index] = 1.0 / (sd * sd)

    for name in ("shape", "expression", "albedo"):
        normal(sl[name], 0.0, 1.0)
    a = sl["angles"].start
    for i, sd in enumerate((c.yaw_sigma, c.pitch_sigma, c.roll_sigma)):
        normal(a + i, 0.0, sd)
    t = sl["translation"].start
    normal(t, 0.0, c.translation_sigma)
    normal(t + 1, 0.0, c.translation_sigma)
    d = float(p.view.translation[2]) - x[t + 2]
    gd, hd = _lognormal_terms(d, c.distance_median, c.distance_log_sigma)
    g[t + 2], h[t + 2] = -gd, hd  # t_z = view_z - d
    f = sl["focal_length"].start
    g[f], h[f] = _lognormal_terms(x[f], c.focal_median, c.focal_log_sigma)
    normal(sl["principal_point"], 0.0, c.principal_point_sigma)
    mean, sd = LogPrior(c).light_gaussian(layout.n_light)
    normal(sl["light"], mean.reshape(-1), sd.reshape(-1))
    for i in range(3):
        j = sl["gain"].start + i
        g[j], h[j] = _lognormal_terms(x[j], 1.0, c.gain_log_sigma)
    normal(sl["contrast"], 1.0, c.contrast_sigma)
    normal(sl["offset"], 0.0, c.offset_sigma)
    e = sl["specular_exponent"].start
    g[e], h[e] = _lognormal_terms(x[e], c.specular_median, c.specular_log_sigma)
    if layout.directional:
        idx = np.r_[sl["light_angles"], sl["light_intensity"]]
        _, g[idx], h[idx] = directional_prior(x[sl["light_angles"]], x[sl["light_intensity"]], c)
    return g, np.diag(h)


def _landmark_pixels(x, inputs, layout: SceneLayout, orthographic: bool):
    """Projected landmark pixels (k, 2) as a JAX function of the scene vector ``x``."""
    mean, sb, eb, camera, view_r, view_t, near, scaling = inputs
    sl = layout.slices()
    k = mean.shape[0]
    pts = mean + (sb @ x[sl["shape"]] + eb @ x[sl["expression"]]).reshape(k, 3)
    yaw, pitch, roll = (x[sl["angles"]][i] for i in range(3))
    rot = view_r @ euler_rotation_jax(roll, yaw, pitch) * scaling
    eye = pts @ rot.T + (view_r @ x[sl["translation"]] + view_t)
    sx, sy, w, h = camera[0], camera[1], camera[2], camera[3]
    pp = x[sl["principal_point"]]
    cx, cy = 0.5 * w * (1.0 + pp[0]), 0.5 * h * (1.0 - pp[1])
    f = x[sl["focal_length"]][0]
    depth = jnp.full_like(eye[:, 2], near) if orthographic else -eye[:, 2]
    return jnp.stack([cx + w * f / sx * eye[:, 0] / depth, cy - h * f / sy * eye[:, 1] / depth],
                     axis=1)


@functools.cache
def _landmark_jacobian(layout: SceneLayout, orthographic: bool):
    def f(x, inputs):
        return _landmark_pixels(x, inputs, layout, orthographic)
    return jax.jit(f), jax.jit(jax.jacfwd(f))


@functools.cache
def _landmark_pullback(layout: SceneLayout, orthographic: bool):
    """``(x, inputs, observed, weights) -> -J^T (weights (px - observed))``: one reverse pass."""
    def g(x, inputs, observed, weights):
        px, pullback = jax.vjp(lambda xx: _landmark_pixels(xx, inputs, layout, orthographic), x)
        return pullback(-weights[:, None] * (px - observed))[0]
    return jax.jit(g)


def _landmark_weights(factor: LandmarkTarget, visible: np.ndarray) -> np.ndarray:
    """Per-landmark weights ``1 / sigma^2`` of the visible landmarks, 0 for hidden ones (k,)."""
    sigma = np.broadcast_to(np.asarray(factor.sigma, np.float64), (len(factor.names),))
    return np.where(visible, 1.0 / sigma ** 2, 0.0)


class PosteriorCurvature:
    """Gradient and Gauss-Newton precision of a face posterior over a fixed pixel region.

    Parameters
    ----------
    target : FaceTarget
        Its image likelihood must have a ``region``; its landmark factor (a
        :class:`~mcmcfit.targets.landmarks.LandmarkTarget` or none; a face box
        falls back to central differences) and prior complete the posterior.
    layout : SceneLayout
    caster : SceneCaster, optional
        Shared private ray caster (one is made otherwise).
    """

    def __init__(self, target: FaceTarget, layout: SceneLayout, *,
                 caster: SceneCaster | None = None):
        lik = target.image_likelihood
        if lik is None or lik.region is None:
            raise InputError("the posterior curvature needs an image likelihood over a region")
        self.target, self.layout = target, layout
        r = target.renderer
        self.jacobian = PixelJacobian(r.model, layout, specular=r.specular,
                                      background=r.background, shadows=r.shadows,
                                      directional_specular_map=r.directional_specular_map)
        self.caster = caster or SceneCaster(r.model)
        self._region = np.flatnonzero(np.asarray(lik.region, bool).reshape(-1))
        self._target = lik.target.linear.reshape(-1, 3)
        self._landmark_inputs = None
        self._region_target = None

    @property
    def region_pixels(self) -> np.ndarray:
        """Row-major indices of the region's pixels."""
        return self._region

    # -- parts ---------------------------------------------------------------------
    def image(self, params: RenderParameter, *, pixels: np.ndarray | None = None,
              weight: float = 1.0) -> Curvature:
        """Return the image part over the region (or ``pixels`` of it, counted ``weight`` times)."""
        lik = self.target.image_likelihood
        p = params
        w = int(p.image_size.width)
        prim, _ = self.caster.cast(p)
        pix = self._region if pixels is None else np.asarray(pixels, np.int64)
        pix = pix[prim[pix] >= 0]  # a region pixel the render misses has no derivative
        if pix.size == 0:
            return Curvature(np.zeros(self.layout.size),
                             np.zeros((self.layout.size, self.layout.size)), 0)
        colours, jac = self.jacobian.jacobian(p, hits_at(prim, pix, w, self._shadow(p, pix)))
        n = pix.size
        rgb = np.asarray(colours[:, :n], np.float64).T
        r = (rgb - self._target[pix]).reshape(-1)  # (3C,)
        j = np.asarray(jac[:, :n], np.float64).transpose(1, 0, 2).reshape(-1, self.layout.size)
        scale = weight / (lik.sigma * lik.sigma * lik.temperature)
        face = face_weights(lik, pix, rgb, self._target[pix])
        if face is not None:  # robust: each pixel weighted by its probability of being the face
            face = np.repeat(face, 3)
            return Curvature(-scale * (j.T @ (face * r)), scale * (j.T @ (face[:, None] * j)), n)
        return Curvature(-scale * (j.T @ r), scale * (j.T @ j), n)

    def _shadow(self, params: RenderParameter, pixels: np.ndarray) -> np.ndarray | None:
        """Return the directional light's visibility at ``pixels`` (None without cast shadows)."""
        if not (self.jacobian.shadows and params.directional_light.enabled):
            return None
        r = self.target.renderer
        return self.caster.shadow(params, pixels, rays=r.shadow_rays, spread_deg=r.shadow_spread_deg)

    def _landmark_arrays(self, factor: LandmarkTarget, params: RenderParameter):
        if self._landmark_inputs is None:
            m, lay = self.target.renderer.model, self.layout
            vid = m.landmark_vertices
            rows = np.concatenate([np.arange(3 * vid[n], 3 * vid[n] + 3) for n in factor.names])
            mean = m.shape.mean[rows].astype(np.float64)
            eb = np.zeros((rows.size, lay.n_expression))
            if m.expression is not None and lay.n_expression:
                mean = mean + m.expression.mean[rows]
                eb = m.expression.scaled_basis[rows, :lay.n_expression]
            self._landmark_inputs = (mean.reshape(-1, 3),
                                     m.shape.scaled_basis[rows, :lay.n_shape].astype(np.float64),
                                     eb.astype(np.float64))
        p = params
        rv, tv = eye_from_world(p.view)
        camera = np.array([p.camera.sensor_size[0], p.camera.sensor_size[1], p.image_size.width,
                           p.image_size.height])
        return (*self._landmark_inputs, camera, rv, tv, float(p.camera.near),
                float(p.pose.scaling))

    def region_triangles(self, params: RenderParameter) -> np.ndarray:
        """Return the triangle (-1: miss) each region pixel sees at ``params`` (a private ray cast)."""
        return self.caster.cast_pixels(params, self._region)

    def image_gradient(self, params: RenderParameter,
                       triangles: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """Return the image log likelihood over the region and its gradient (D,) (reverse mode).

        Parameters
        ----------
        params : RenderParameter
        triangles : (region pixels,) int, optional
            The triangle each region pixel is rendered with. By default those a
            ray cast at ``params`` itself sees (only the region's rays are cast):
            the exact likelihood and its gradient. Given (e.g. those of the
            mode, :meth:`region_triangles`), the pixels keep them, each
            triangle's plane extrapolated: a fixed smooth surrogate of the
            likelihood, whose gradient has none of the jumps of the exact one
            where a pixel's ray crosses from one triangle to the next.

        Returns
        -------
        (float, (D,) float64)
            A region pixel without a triangle contributes its constant term and
            no derivative. The value omits the Gaussian normaliser and is summed
            in float32 (for proposals, not for the acceptance test).
        """
        lik = self.target.image_likelihood
        p = params
        w = int(p.image_size.width)
        pix = self._region
        prim = np.full(int(p.image_size.width) * int(p.image_size.height), -1, np.int64)
        prim[pix] = self.caster.cast_pixels(p, pix) if triangles is None else triangles
        hits = hits_at(prim, pix, w, self._shadow(p, pix))
        n = pix.size
        c = hits.mask.shape[0]
        if self._region_target is None or self._region_target.shape[1] != c:
            target = np.zeros((3, c), np.float32)
            target[:, :n] = self._target[pix].T
            self._region_target = jnp.asarray(target)
        hit = np.asarray(prim[pix] >= 0)
        weight, outlier = readout_weights(lik, pix, hit, c)
        if outlier is None:
            value, grad = self.jacobian.gaussian_value_and_grad(p, hits, self._region_target,
                                                                weight)
        else:
            value, grad = self.jacobian.robust_value_and_grad(
                p, hits, self._region_target, weight, outlier, 1.0 / (lik.sigma * lik.sigma))
        missed = ~hit
        if missed.any():
            bg = np.asarray(self.target.renderer.background, np.float64)
            d2 = np.sum((self._target[pix[missed]] - bg) ** 2, axis=1)
            value += missed_value(lik, d2, None if outlier is None else outlier[:n][missed])
        return value, grad

    def value_and_gradient(self, params: RenderParameter,
                           triangles: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """Return the log posterior (up to constants, see :meth:`image_gradient`) and its gradient in x."""
        value, grad = self.image_gradient(params, triangles)
        lm_value, lm_grad = self._landmark_value_and_gradient(params)
        gp, _ = prior_curvature(params, self.layout, self.target.prior.config)
        return value + lm_value + float(self.target.log_prior(params)), grad + lm_grad + gp

    def _landmark_value_and_gradient(self, params: RenderParameter) -> tuple[float, np.ndarray]:
        """Return the landmark log likelihood and its gradient (visibility held): one projection."""
        factor = self.target.landmarks
        if not isinstance(factor, LandmarkTarget):
            return float(self.target.log_lik_landmarks(params)), self.landmarks(params).gradient
        px, visible = factor.project(params)
        weights = _landmark_weights(factor, visible)
        pullback = _landmark_pullback(self.layout, bool(params.camera.orthographic))
        with jax.enable_x64(True):
            x = jnp.asarray(self.layout.vector(params), jnp.float64)
            grad = np.asarray(pullback(x, self._landmark_arrays(factor, params),
                                       np.asarray(factor.observed, np.float64), weights),
                              np.float64)
        return float(factor.log_lik_of(px, visible)), grad

    def landmarks(self, params: RenderParameter) -> Curvature:
        """Return the landmark part (Gauss-Newton with the visibility at ``params``)."""
        factor = self.target.landmarks
        size = self.layout.size
        if factor is None:
            return Curvature(np.zeros(size), np.zeros((size, size)))
        if not isinstance(factor, LandmarkTarget):
            return self._finite_difference(params)
        _, visible = factor.project(params)
        inputs = self._landmark_arrays(factor, params)
        value_fn, jac_fn = _landmark_jacobian(self.layout, bool(params.camera.orthographic))
        with jax.enable_x64(True):
            x = jnp.asarray(self.layout.vector(params), jnp.float64)
            px = np.asarray(value_fn(x, inputs), np.float64)
            jac = np.asarray(jac_fn(x, inputs), np.float64)  # (k, 2, D)
        wts = _landmark_weights(factor, visible)
        r = (px - factor.observed) * np.sqrt(wts)[:, None]
        j = jac * np.sqrt(wts)[:, None, None]
        j = j.reshape(-1, size)
        return Curvature(-(j.T @ r.reshape(-1)), j.T @ j)

    def _finite_difference(self, params: RenderParameter) -> Curvature:
        """Central-difference gradient and Gauss-Newton-free (diagonal) curvature of a face box."""
        size = self.layout.size
        sl = self.layout.slices()
        idx = np.r_[sl["shape"], sl["expression"], sl["angles"], sl["translation"],
                    sl["focal_length"], sl["principal_point"]]
        x = self.layout.vector(params)
        f = self.target.log_lik_landmarks
        g, h = np.zeros(size), np.zeros(size)
        f0 = f(params)
        for i in idx:
            step = 1e-4 * max(1.0, abs(x[i]))
            up, down = x.copy(), x.copy()
            up[i] += step
            down[i] -= step
            fu = f(self.layout.with_vector(params, up))
            fd = f(self.layout.with_vector(params, down))
            g[i] = (fu - fd) / (2 * step)
            h[i] = max(0.0, -(fu - 2 * f0 + fd) / (step * step))
        return Curvature(g, np.diag(h))

    # -- all ------------------------------------------------------------------------
    def at(self, params: RenderParameter, *, pixels: np.ndarray | None = None,
           weight: float = 1.0) -> Curvature:
        """Return the whole posterior's gradient and precision at ``params`` (see the module notes).

        ``pixels`` (a subset of the region) and ``weight`` trade accuracy for
        time: a random tenth of the region counted ten times estimates the
        image part without bias.
        """
        img = self.image(params, pixels=pixels, weight=weight)
        lm = self.landmarks(params)
        gp, hp = prior_curvature(params, self.layout, self.target.prior.config)
        prec = img.precision + lm.precision + hp
        return Curvature(img.gradient + lm.gradient + gp, 0.5 * (prec + prec.T), img.pixels, gp)


def coordinate_gradient(curvature: PosteriorCurvature, coords,
                        triangles: np.ndarray | None = None):
    """Return ``grad(params) -> (log density, gradient)`` in the sampling coordinates ``coords``.

    ``coords`` is a :class:`proposals.laplace.coordinates.SamplingCoordinates` of the same
    scene layout; the density includes ``log |dx/du|``; ``triangles`` as
    :meth:`PosteriorCurvature.image_gradient`. For :class:`proposals.laplace.moves.GaussianHMC`.
    """
    def grad(params: RenderParameter) -> tuple[float, np.ndarray]:
        value, g = curvature.value_and_gradient(params, triangles)
        u = coords.u_of(params)
        return value + coords.log_jacobian(u), coords.gradient(g, u)
    return grad
