"""The Laplace approximation widened where warm-up draws are wider: low-rank metric adaptation.

The Gaussian moves (:mod:`proposals.laplace.moves`) whiten the posterior with
its Laplace approximation ``N(m, L L^T)``. Where the posterior is wider than
the approximation along a few directions (a Gauss-Newton precision at the mode
overstates the curvature of a nearly flat valley, e.g. face size against
focal length and distance), every move crawls along them: an HMC trajectory
of whitened length ``T`` turns by only ``T / s`` radians in a direction of sd
``s``, so draws there are correlated across many moves.

:func:`widened_by_draws` measures the warm-up draws' covariance in the
approximation's whitened coordinates ``z = L^-1 (u - m)``, keeps the
eigen-directions whose variance stands clear of what sampling noise alone
gives a ``d``-dimensional identity covariance (the Marchenko-Pastur edge
``(1 + sqrt(d / n))^2``, Baik, Ben Arous & Peche 2005 for a detectable spike),
and returns the approximation with those directions' variances set to the
measured ones (capped). All other directions keep the Laplace approximation:
a full sample covariance from a few hundred correlated draws in ~130
dimensions would be mostly noise.

Used once, during the warm-up; the approximation is then frozen for the kept
draws, so the kept chain stays time-homogeneous.

:func:`widened_by_curvature` widens it before any draw, from the posterior's
own curvature averaged over about one sd around the mode (a Hessian by
central differences of the exact gradient, in the same whitened
coordinates): a Gauss-Newton precision drops the residuals' second-order
term, which a model that does not span the photograph (a held-out face: large,
structured residuals) makes negative along a few directions, so there the
posterior is many times wider than the approximation.

This module imports :mod:`albedo_model.errors` and :mod:`proposals.laplace.moves`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from proposals.laplace.moves import GaussianApproximation

__all__ = ["CURVATURE_MAX_RATIO", "FISHER_SHRINKAGE", "FISHER_THRESHOLD", "MAX_DIRECTIONS",
           "MAX_RATIO", "Widening", "widened_by_curvature", "widened_by_draws", "widened_by_fisher"]

#: At most this many directions are widened.
MAX_DIRECTIONS = 4
#: A direction's variance ratio is capped here (a far-out warm-up excursion is not the posterior).
MAX_RATIO = 9.0
#: A direction is widened only when its ratio exceeds this factor times the noise edge.
MARGIN = 1.2
#: :func:`widened_by_curvature` caps a direction's variance ratio here (flat or negative
#: curvature: the prior, not the mode's neighbourhood, bounds the posterior there).
CURVATURE_MAX_RATIO = 25.0
#: :func:`widened_by_fisher` shrinks both whitened covariances towards the identity with
#: this many pseudo-draws (at ~300 draws in ~140 dimensions the top direction of the
#: estimate overlapped the converged posterior's 0.83-0.84 with 10 or 50, 0.04 with none).
FISHER_SHRINKAGE = 10.0
#: :func:`widened_by_fisher` widens a direction whose estimated variance ratio exceeds this.
FISHER_THRESHOLD = 2.0


class Widening(NamedTuple):
    """What :func:`widened_by_draws` found.

    Attributes
    ----------
    approx : GaussianApproximation
        The widened approximation (the input when nothing was widened).
    ratios : (k,) float
        Variance ratios (draws / approximation) of the widened directions.
    directions : (d, k) float
        Their unit vectors in the approximation's whitened coordinates.
    largest : float
        The largest eigenvalue of the draws' whitened covariance.
    edge : float
        The noise edge the eigenvalues were compared with.
    n_draws : int
    """

    approx: GaussianApproximation
    ratios: np.ndarray
    directions: np.ndarray
    largest: float
    edge: float
    n_draws: int


def widened_by_draws(approx: GaussianApproximation, draws: list[np.ndarray] | np.ndarray, *,
                     effective_fraction: float = 0.25,
                     max_directions: int = MAX_DIRECTIONS) -> Widening:
    """Return ``approx`` widened along the directions where ``draws`` are wider.

    Parameters
    ----------
    approx : GaussianApproximation
        ``N(m, L L^T)`` in the sampling coordinates.
    draws : (n, d) array or list of such arrays
        Warm-up draws in the same coordinates, one array per chain; each is
        centred on its own mean (chains with slightly different modes add no
        spread).
    effective_fraction : float in (0, 1]
        Effective draws per draw assumed for the noise edge (correlated draws
        spread the noise eigenvalues as fewer independent ones would).
    max_directions : int

    Returns
    -------
    Widening

    Raises
    ------
    InputError
        Draws of the wrong dimension, not finite, or fewer than 2 per chain.
    """
    parts = [np.asarray(d, np.float64) for d in (draws if isinstance(draws, list) else [draws])]
    d = approx.size
    for p in parts:
        if p.ndim != 2 or p.shape[1] != d or p.shape[0] < 2 or not np.all(np.isfinite(p)):
            raise InputError(f"widening needs finite (n >= 2, {d}) draws per chain; "
                             f"got {p.shape}")
    if not 0.0 < effective_fraction <= 1.0:
        raise InputError(f"effective_fraction must be in (0, 1], got {effective_fraction!r}")
    centred = np.concatenate([p - p.mean(axis=0) for p in parts])
    n = centred.shape[0] - len(parts)  # degrees of freedom after the per-chain means
    z = np.linalg.solve(approx.chol_cov, centred.T)  # (d, N) whitened
    cov = (z @ z.T) / max(1, n)
    values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
    n_eff = max(1.0, effective_fraction * n)
    edge = (1.0 + math.sqrt(d / n_eff)) ** 2
    return _widened_above(approx, values, vectors, MARGIN * edge, max_directions, edge, n)


def _widened_above(approx: GaussianApproximation, values: np.ndarray, vectors: np.ndarray,
                   cut: float, max_directions: int, edge: float, n: int) -> Widening:
    """Return ``approx`` widened where an eigenvalue of a whitened covariance exceeds ``cut``.

    ``values`` ascending with their ``vectors`` (as ``eigh`` returns them); at most
    ``max_directions`` directions, each ratio capped at :data:`MAX_RATIO`.
    """
    keep = [i for i in range(values.size - 1, -1, -1) if values[i] > cut][:max_directions]
    if not keep:
        return Widening(approx, np.zeros(0), np.zeros((values.size, 0)), float(values[-1]),
                        edge, n)
    ratios = np.minimum(values[keep], MAX_RATIO)
    v = vectors[:, keep]
    return Widening(_widened(approx, ratios, v), ratios, v, float(values[-1]), edge, n)


def _widened(approx: GaussianApproximation, ratios: np.ndarray,
             v: np.ndarray) -> GaussianApproximation:
    """Return ``approx`` with variance ratios ``ratios`` along the whitened unit vectors ``v``."""
    # Covariance L (I + V (r - 1) V^T) L^T; its precision is
    # P + L^-T V (1/r - 1) V^T L^-1 with P = L^-T L^-1 the approximation's.
    w = np.linalg.solve(approx.chol_cov.T, v)  # L^-T V
    precision = approx.precision + (w * (1.0 / ratios - 1.0)) @ w.T
    return GaussianApproximation(approx.mean, 0.5 * (precision + precision.T))


def widened_by_curvature(approx: GaussianApproximation, whitened_precision: np.ndarray, *,
                         max_ratio: float = CURVATURE_MAX_RATIO) -> Widening:
    """Return ``approx`` widened along the directions where the posterior is flatter than it.

    Parameters
    ----------
    approx : GaussianApproximation
        ``N(m, L L^T)`` in the sampling coordinates.
    whitened_precision : (d, d) array
        The posterior's negative Hessian in the whitened coordinates
        ``z = L^-1 (u - m)`` (the identity where the posterior is the
        approximation), e.g. by central differences of its gradient.
    max_ratio : float > 1
        Cap of a direction's variance ratio (eigenvalues at or below
        ``1 / max_ratio``, negative ones included, get it).

    Returns
    -------
    Widening
        Every eigen-direction with eigenvalue ``lambda < 1`` widened by
        ``1 / max(lambda, 1 / max_ratio)``; the others keep the approximation
        (it is only ever widened: where the posterior is more curved than a
        Gauss-Newton precision, the difference is sampling noise or small).
        ``largest`` is the largest ratio, ``edge`` 1 and ``n_draws`` 0.

    Raises
    ------
    InputError
        A matrix of the wrong shape or not finite, or ``max_ratio <= 1``.
    """
    h = np.asarray(whitened_precision, np.float64)
    d = approx.size
    if h.shape != (d, d) or not np.all(np.isfinite(h)):
        raise InputError(f"widening needs a finite ({d}, {d}) whitened precision; got {h.shape}")
    if not (math.isfinite(max_ratio) and max_ratio > 1.0):
        raise InputError(f"max_ratio must be a number > 1, got {max_ratio!r}")
    values, vectors = np.linalg.eigh(0.5 * (h + h.T))
    keep = values < 1.0 - 1e-6  # not rounding of an unchanged direction
    if not np.any(keep):
        return Widening(approx, np.zeros(0), np.zeros((d, 0)), 1.0, 1.0, 0)
    ratios = 1.0 / np.maximum(values[keep], 1.0 / max_ratio)
    v = vectors[:, keep]
    return Widening(_widened(approx, ratios, v), ratios, v, float(ratios.max()), 1.0, 0)


def widened_by_fisher(approx: GaussianApproximation, draws: list[np.ndarray],
                      gradients: list[np.ndarray], *, shrinkage: float = FISHER_SHRINKAGE,
                      threshold: float = FISHER_THRESHOLD,
                      max_directions: int = MAX_DIRECTIONS) -> Widening:
    """Return ``approx`` widened where draws *and* their log-density gradients say it is too narrow.

    For a Gaussian target ``N(mu, S)`` the draws' covariance is ``S`` and the
    gradients' covariance is ``S^-1`` (the Fisher identity), so each estimate
    alone is noisy but the covariance that best agrees with both -- the one
    minimising the Fisher divergence over affine preconditioners, ``S`` with
    ``S G S = X``, i.e. the matrix geometric mean of ``X`` and ``G^-1``
    (Seyboldt, Carlson & Carpenter 2025, "Preconditioning Hamiltonian Monte
    Carlo by minimizing Fisher divergence") -- finds a wide direction from a few
    hundred correlated warm-up draws where the draws alone do not. Both
    covariances are taken in the approximation's whitened coordinates and
    shrunk towards the identity with ``shrinkage`` pseudo-draws; the
    eigen-directions of the estimate whose variance ratio exceeds
    ``threshold`` (at most ``max_directions``, capped at :data:`MAX_RATIO`) are
    widened to it, all others keep the approximation.

    Parameters
    ----------
    approx : GaussianApproximation
        ``N(m, L L^T)`` in the sampling coordinates.
    draws, gradients : list of (n_i, d) arrays
        One array per chain: warm-up draws in the sampling coordinates and the
        gradient of the log density (in the same coordinates) at each of them.
    shrinkage : float >= 0
    threshold : float > 1
    max_directions : int

    Returns
    -------
    Widening
        ``largest`` is the estimate's largest variance ratio, ``edge`` the threshold.

    Raises
    ------
    InputError
        Mismatched, non-finite or too few (< 2 per chain) draws or gradients.
    """
    d = approx.size
    xs = [np.asarray(x, np.float64) for x in draws]
    gs = [np.asarray(g, np.float64) for g in gradients]
    if len(xs) != len(gs) or not xs:
        raise InputError(f"Fisher widening needs one gradient array per draw array; got "
                         f"{len(xs)} and {len(gs)}")
    for x, g in zip(xs, gs):
        if (x.ndim != 2 or x.shape != g.shape or x.shape[1] != d or x.shape[0] < 2
                or not (np.all(np.isfinite(x)) and np.all(np.isfinite(g)))):
            raise InputError(f"Fisher widening needs finite (n >= 2, {d}) draws and gradients "
                             f"per chain; got {x.shape} and {g.shape}")
    if not (math.isfinite(threshold) and threshold > 1.0) or not shrinkage >= 0.0:
        raise InputError(f"Fisher widening needs threshold > 1 and shrinkage >= 0; got "
                         f"{threshold!r} and {shrinkage!r}")
    lc = approx.chol_cov
    z = np.concatenate([np.linalg.solve(lc, (x - x.mean(axis=0)).T).T for x in xs])
    h = np.concatenate([(g - g.mean(axis=0)) @ lc for g in gs])  # L^T g per row
    n = z.shape[0] - len(xs)
    eye = np.eye(d)
    cx = (z.T @ z + shrinkage * eye) / (n + shrinkage)
    cg = (h.T @ h + shrinkage * eye) / (n + shrinkage)
    cg_half = _spd_power(cg, 0.5)
    cg_inv_half = _spd_power(cg, -0.5)
    estimate = cg_inv_half @ _spd_power(cg_half @ cx @ cg_half, 0.5) @ cg_inv_half
    values, vectors = np.linalg.eigh(0.5 * (estimate + estimate.T))
    return _widened_above(approx, values, vectors, threshold, max_directions, threshold, n)


def _spd_power(a: np.ndarray, power: float) -> np.ndarray:
    """Return ``a ** power`` of a symmetric positive definite matrix (by its eigen-decomposition)."""
    values, vectors = np.linalg.eigh(0.5 * (a + a.T))
    return (vectors * np.maximum(values, 1e-300) ** power) @ vectors.T
