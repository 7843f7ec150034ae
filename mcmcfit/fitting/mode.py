"""The posterior's mode and its Laplace approximation: Levenberg-Marquardt in the sampling coordinates.

Before the kept draws, every chain climbs to the posterior mode with
Levenberg-Marquardt steps in the sampling coordinates ``u``
(:class:`~proposals.laplace.coordinates.SamplingCoordinates`): the step solves
``(P + lambda diag P) du = g`` with the gradient ``g`` and Gauss-Newton
precision ``P`` of :class:`~mcmcfit.targets.curvature.PosteriorCurvature`, and
is kept only if the **exact** log density (ray cast, prior, landmarks, in
``u``: plus ``log |dx/du|``) rises; otherwise ``lambda`` grows. ``P`` comes
from the pixel Jacobian of a random part of the region's pixels, counted up
(0.17-0.3 s a step at 250^2); given the exact gradient over every region pixel (one
reverse pass, ~30 ms) a climb takes it on every step and re-evaluates ``P``
only every few steps, so its steps are cheaper and its direction carries no
subset noise. A handful of steps reach the mode from the landmark fit where
thousands of random-walk steps do not.

:func:`laplace` then returns the Gaussian ``N(u* + P^-1 g, P^-1)`` at the mode
(all region pixels): the reference of the Gaussian moves
(:mod:`proposals.laplace.moves`).

This module imports :mod:`albedo_model` (errors, params, render.region),
:mod:`mcmcfit.sampling.kernel`, :mod:`mcmcfit.targets` (curvature, face) and
:mod:`proposals` (coordinates, gaussian).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from albedo_model.params import RenderParameter
from albedo_model.camera import pixel_scale
from albedo_model.render.region import contour_jump, fold_contours, interior_region
from mcmcfit.sampling.kernel import init
from mcmcfit.targets.curvature import PosteriorCurvature, SceneCaster
from mcmcfit.targets.face import FaceTarget
from proposals.laplace.coordinates import SamplingCoordinates
from proposals.laplace.moves import GaussianApproximation

__all__ = ["ADOPT_GAP", "POLISH_STEPS", "ModeResult", "find_mode", "laplace", "region_of"]

#: Log-density gap (nats) beyond which a chain climbs from the best chain's mode instead of its
#: own: a local mode that much lower (at similar curvature) holds under e^-10 of the mass, and
#: a chain started there spends the fit finding its way out.
ADOPT_GAP = 10.0

#: Levenberg-Marquardt steps over every region pixel that end each climb under the final
#: posterior (the subset steps before them are noisy near the mode).
POLISH_STEPS = 3

#: Region pixels a Levenberg-Marquardt step reads at most (a random subset, counted up).
STEP_PIXELS = 4000

#: Accepted steps a climb with the exact gradient keeps one precision for (see :func:`find_mode`).
REFRESH_STEPS = 4

#: ``params -> (log density, gradient in the sampling coordinates)``.
CoordinateGradient = Callable[[RenderParameter], tuple[float, np.ndarray]]


class ModeResult(NamedTuple):
    """Where the climb ended.

    Attributes
    ----------
    params : RenderParameter
    log_density : float
        Exact log posterior density in the sampling coordinates at ``params``.
    iterations : int
        Accepted steps.
    trace : tuple of float
        The log density after each accepted step (the start first).
    """

    params: RenderParameter
    log_density: float
    iterations: int
    trace: tuple[float, ...]


def region_of(caster: SceneCaster, params: RenderParameter, usable: np.ndarray | None = None,
              **kwargs) -> np.ndarray:
    """Return the interior region (H W,) bool of the render of ``params`` (see :mod:`albedo_model.render.region`).

    Pixels near the silhouette, near depth jumps and near the mesh's visible
    fold edges are left out.
    """
    prim, t = caster.cast(params)
    w, h = int(params.image_size.width), int(params.image_size.height)
    model = caster.model
    vertices = model.shape_instance(params.momo.shape, params.momo.expression)
    jump = contour_jump(min(pixel_scale(params.camera, params.image_size)))
    kwargs.setdefault("jump", jump)
    folds = fold_contours(params, vertices, model.triangles, t, tolerance=kwargs["jump"])
    return interior_region(prim, t, w, h, usable=usable, folds=folds, **kwargs)


def _exact(target: FaceTarget, coords: SamplingCoordinates, params: RenderParameter,
           u: np.ndarray) -> float:
    state = init(params, target, image=True)
    value = state.log_posterior + coords.log_jacobian(u)
    return value if math.isfinite(value) else -math.inf


def _full_gradient(gradient: CoordinateGradient, params: RenderParameter) -> np.ndarray | None:
    """Return ``gradient(params)``'s gradient, or None where it is not finite."""
    _, g = gradient(params)
    g = np.asarray(g, np.float64)
    return g if np.all(np.isfinite(g)) else None


def find_mode(target: FaceTarget, curvature: PosteriorCurvature, coords: SamplingCoordinates,
              params: RenderParameter, *, rng: np.random.Generator, max_steps: int = 10,
              tolerance: float = 0.1, step_pixels: int = STEP_PIXELS,
              free: np.ndarray | None = None, gradient: CoordinateGradient | None = None,
              refresh: int = REFRESH_STEPS) -> ModeResult:
    """Climb from ``params`` to the mode of ``target``'s posterior (see the module notes).

    Parameters
    ----------
    target : FaceTarget
        The posterior (image likelihood over a fixed region).
    curvature : PosteriorCurvature
        Of the same target.
    coords : SamplingCoordinates
    params : RenderParameter
    rng : numpy Generator
        Draws the pixel subsets of the steps.
    max_steps : int
        Most accepted steps.
    tolerance : float
        Stop when a step gains less log density than this.
    step_pixels : int
        Region pixels per step (a random subset when the region is larger).
    free : (d,) bool, optional
        Move only these coordinates (the others held; default all): the
        conditional mode of the free ones.
    gradient : callable, optional
        ``params -> (log density, gradient in u)`` over every region pixel
        (:func:`~mcmcfit.targets.curvature.coordinate_gradient`, one reverse
        pass). With it each step takes this exact gradient and the precision of
        the last Jacobian evaluation, re-evaluated every ``refresh`` accepted
        steps, and before the climb ends on a step that failed or gained less
        than ``tolerance`` at a kept precision; without it every step evaluates
        both over a pixel subset.
    refresh : int
        Accepted steps between two precision evaluations (with ``gradient``).

    Returns
    -------
    ModeResult
        The renderer's accepted state is left at an arbitrary evaluated point:
        re-initialise the chain after calling this.
    """
    u = coords.u_of(params)
    value = _exact(target, coords, params, u)
    trace = [value]
    lam = 1e-3
    region = curvature.region_pixels
    steps = 0
    prec, age = None, 0
    for _ in range(max_steps):
        g = None if gradient is None else _full_gradient(gradient, params)
        fresh = g is None or prec is None or age >= refresh
        if fresh:
            if region.size > step_pixels:
                pixels = rng.choice(region, step_pixels, replace=False)
                weight = region.size / step_pixels
            else:
                pixels, weight = None, 1.0
            cur = curvature.at(params, pixels=pixels, weight=weight)
            g_sub, prec = coords.to_coordinates(cur.gradient, cur.precision, u,
                                                second_order=cur.exact_gradient)
            g = g_sub if g is None else g
            age = 0
        h = prec
        if free is not None:
            g, h = g[free], prec[np.ix_(free, free)]
        diag = np.maximum(np.diag(h), 1e-12)
        lam_start, moved = lam, False
        for _ in range(12):
            try:
                step = np.linalg.solve(h + lam * np.diag(diag), g)
            except np.linalg.LinAlgError:
                lam *= 4.0
                continue
            if free is None:
                du = step
            else:
                du = np.zeros_like(u)
                du[free] = step
            u_new = u + du
            p_new = coords.params_of(u_new, params)
            v_new = _exact(target, coords, p_new, u_new)
            if v_new > value:
                moved = True
                break
            lam *= 4.0
        if not moved:
            if not fresh:  # the kept precision may be stale: re-evaluate it first
                lam, age = lam_start, refresh
                continue
            break
        age += 1
        gain = v_new - value
        u, params, value = u_new, p_new, v_new
        trace.append(value)
        steps += 1
        lam = max(lam / 4.0, 1e-7)
        if gain < tolerance:
            if not fresh:  # a small gain at a kept precision: stop only after a fresh one
                age = refresh
                continue
            break
    return ModeResult(params, value, steps, tuple(trace))


def laplace(curvature: PosteriorCurvature, coords: SamplingCoordinates,
            params: RenderParameter) -> GaussianApproximation:
    """Return the Laplace approximation ``N(u + P^-1 g, P^-1)`` at ``params`` (all region pixels).

    The precision is the Gauss-Newton one of the likelihoods plus the prior's
    exact one, positive definite by construction; eigenvalues below 1e-12 of
    the largest (rounding) are raised to it.
    """
    u = coords.u_of(params)
    cur = curvature.at(params)
    g, prec = coords.to_coordinates(cur.gradient, cur.precision, u,
                                    second_order=cur.exact_gradient)
    prec = 0.5 * (prec + prec.T)
    w, v = np.linalg.eigh(prec)
    floor = 1e-12 * max(float(w.max()), 1e-300)
    if w.min() < floor:
        prec = (v * np.maximum(w, floor)) @ v.T
    mean = u + np.linalg.solve(prec, g)
    return GaussianApproximation(mean, prec)
