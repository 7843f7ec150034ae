"""The Laplace approximation widened by the posterior's curvature around the mode.

A Gauss-Newton precision ``J^T J / sigma^2`` leaves out the residuals'
second-order term ``sum r_i d2 r_i``. For a face the model spans (the demo)
the residuals are noise and the term is negligible; for a held-out face
(freckles, stubble, shadows: large, spatially structured residuals) it is
negative along a few directions of shape against pose, and there the posterior
is many times wider than the approximation (measured on a held-out subject of
the evaluation: 5 of 137 whitened directions with curvature below 0.5, one
negative; the kept draws 51x the approximation's variance along the widest).
Moves whitened by such an approximation crawl along those directions.

:func:`whitened_precision` measures the posterior's negative Hessian in the
approximation's whitened coordinates by central differences of the exact
gradient (the one HMC uses: the ray cast at each point), at +-``scale``
whitened sds: a step of about one sd averages the curvature over the region
the chain explores and over the piecewise-constant visibility (at 0.1 sd the
estimate is dominated by triangles changing under the pixels).
:func:`curvature_widened` widens the approximation along the flat directions
(:func:`proposals.laplace.widening.widened_by_curvature`). It costs ``2 d``
gradient evaluations once per chain (about 11 s for 137 coordinates at 250
px on one core), before the warm-up, so the kept chain's kernel is unchanged by it.

This module imports :mod:`albedo_model.errors` and :mod:`proposals.laplace`
(moves, widening).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from albedo_model.errors import InputError
from proposals.laplace.moves import GaussianApproximation
from proposals.laplace.widening import widened_by_curvature

__all__ = ["FD_SCALE", "curvature_widened", "gradient_in_coordinates", "whitened_precision"]

#: Central-difference step, in whitened sds of the approximation.
FD_SCALE = 1.0

#: How many of the largest ratios and smallest eigenvalues the record keeps.
RECORDED = 8

#: ``u -> (log density, gradient in u)``; non-finite where ``u`` leaves the domain.
CoordinateGradientFn = Callable[[np.ndarray], tuple[float, np.ndarray]]


def gradient_in_coordinates(grad: Callable, coords, base) -> CoordinateGradientFn:
    """Return ``u -> grad(coords.params_of(u, base))``, ``(nan, nan)`` outside the domain.

    ``grad`` is ``params -> (log density, gradient in u)``
    (:func:`mcmcfit.targets.curvature.coordinate_gradient`), ``coords`` a
    :class:`proposals.laplace.coordinates.SamplingCoordinates`.
    """
    def at(u: np.ndarray) -> tuple[float, np.ndarray]:
        nan = (float("nan"), np.full(u.size, np.nan))
        if not (np.all(np.isfinite(u)) and np.isfinite(coords.log_jacobian(u))):
            return nan
        try:
            with np.errstate(all="ignore"):
                return grad(coords.params_of(u, base))
        except (InputError, ValueError, ArithmeticError):
            return nan
    return at


def whitened_precision(gradient: CoordinateGradientFn, approx: GaussianApproximation,
                       centre: np.ndarray, *, scale: float = FD_SCALE) -> np.ndarray:
    """Return the posterior's negative Hessian at ``centre`` in ``approx``'s whitened coordinates.

    Column ``i`` is ``-L^T (g(c + s L e_i) - g(c - s L e_i)) / (2 s)`` with
    ``L`` the approximation's covariance factor; the result is symmetrised. A
    column whose gradients are not finite (a step out of the parameters'
    domain) is taken as the approximation's (``e_i``).

    Parameters
    ----------
    gradient : callable ``u -> (log density, gradient)``
    approx : GaussianApproximation
    centre : (d,) array
        Sampling coordinates (the mode).
    scale : float > 0
        Step in whitened sds.

    Returns
    -------
    (d, d) float array
        The identity where the posterior is the approximation (a Gaussian with
        covariance ``L L^T``).

    Raises
    ------
    InputError
        ``centre`` of the wrong size or not finite, or ``scale <= 0``.
    """
    c = np.asarray(centre, np.float64).reshape(-1)
    d = approx.size
    if c.size != d or not np.all(np.isfinite(c)):
        raise InputError(f"centre must be {d} finite coordinates, got {c.shape}")
    if not (np.isfinite(scale) and scale > 0.0):
        raise InputError(f"scale must be positive, got {scale!r}")
    lc = approx.chol_cov
    out = np.eye(d)
    for i in range(d):
        step = scale * lc[:, i]
        _, g_plus = gradient(c + step)
        _, g_minus = gradient(c - step)
        diff = np.asarray(g_plus, np.float64) - np.asarray(g_minus, np.float64)
        if diff.shape == (d,) and np.all(np.isfinite(diff)):
            out[:, i] = -(lc.T @ diff) / (2.0 * scale)
    return 0.5 * (out + out.T)


def curvature_widened(gradient: CoordinateGradientFn, approx: GaussianApproximation,
                      centre: np.ndarray, *,
                      scale: float = FD_SCALE) -> tuple[GaussianApproximation, dict]:
    """Return ``approx`` widened where the posterior's curvature is flatter, and a record.

    See :func:`whitened_precision` and
    :func:`proposals.laplace.widening.widened_by_curvature`. The record holds
    ``widened`` (how many directions), ``ratios`` (the largest variance
    ratios), ``eigenvalues`` (the smallest of the whitened precision; at most
    :data:`RECORDED` of each), ``scale`` and ``seconds``.
    """
    t0 = time.perf_counter()
    h = whitened_precision(gradient, approx, centre, scale=scale)
    found = widened_by_curvature(approx, h)
    ratios = sorted((float(r) for r in found.ratios), reverse=True)
    record = {"widened": len(ratios), "ratios": ratios[:RECORDED],
              "eigenvalues": [float(x) for x in np.linalg.eigvalsh(h)[:RECORDED]],
              "scale": float(scale), "seconds": time.perf_counter() - t0}
    return found.approx, record
