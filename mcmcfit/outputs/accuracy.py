"""Scores of a fit against a known truth: pose angle error, albedo RMSE and interval coverage.

Coverage is reported for both kinds of interval (:mod:`mcmcfit.outputs.posterior`):
the posterior predictive one (coefficients + the model's residual variance),
which is the headline ``coverage`` when the model has a residual variance, and
the coefficient-only one, always.

This module imports :mod:`albedo_model` (camera, model, params, pca),
:mod:`mcmcfit.outputs.posterior`, :mod:`mcmcfit.outputs.albedo_decoding` and
:mod:`mcmcfit.sampling.param_vector`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from albedo_model.camera import euler_rotation
from albedo_model.model import MorphableModel
from albedo_model.params import Pose
from albedo_model.pca import PCAPart
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.outputs.albedo_decoding import decoded_albedo_posterior
from mcmcfit.outputs.posterior import AlbedoPosterior, albedo_posterior

__all__ = ["AlbedoScore", "albedo_score", "albedo_columns", "interval_error",
           "posterior_interval_error", "pose_error_deg"]


def pose_error_deg(pose: Pose, truth: Pose) -> float:
    """Angle (degrees) of the rotation between two head orientations (geodesic distance)."""
    a = euler_rotation(pose.roll, pose.yaw, pose.pitch)
    b = euler_rotation(truth.roll, truth.yaw, truth.pitch)
    c = (np.trace(a.T @ b) - 1.0) / 2.0
    return math.degrees(math.acos(float(np.clip(c, -1.0, 1.0))))


class AlbedoScore(NamedTuple):
    """Posterior-mean diffuse albedo against the truth on the visible vertices.

    Attributes
    ----------
    rmse : float
        Root mean square error over visible vertices and channels (linear sRGB).
    coverage : float
        Fraction of (vertex, channel) values inside the central interval: the
        predictive one when the model has a residual variance (``predictive``),
        else the coefficient-only one.
    level : float
        Probability of that interval.
    n_samples : int
    coverage_coefficients : float
        Coverage of the coefficient-only interval (equal to ``coverage`` when
        not ``predictive``).
    predictive : bool
        Whether ``coverage`` is that of posterior predictive intervals.
    """

    rmse: float
    coverage: float
    level: float
    n_samples: int
    coverage_coefficients: float = math.nan
    predictive: bool = False


def albedo_columns(layout: ParamLayout) -> slice:
    """Columns of the albedo coefficients ``albedo.0, albedo.1, ...`` in ``layout``."""
    return layout.slice("albedo")


def interval_error(mean, lo, hi, true, visible) -> dict:
    """RMSE, mean absolute error and interval coverage of per-vertex estimates.

    Parameters
    ----------
    mean, lo, hi : (n, 3) float arrays
        Posterior mean and central-interval bounds.
    true : (n, 3) float array
    visible : (n,) bool
        Vertices scored.

    Returns
    -------
    dict
        ``rmse`` and ``mean_abs`` over visible vertices and channels, and
        ``coverage``: the fraction of (vertex, channel) true values inside
        ``[lo, hi]`` (widened by 1e-6 for float32 bounds); NaN with no vertex.
    """
    sel = np.asarray(visible, bool)
    if not sel.any():
        return {"rmse": math.nan, "coverage": math.nan, "mean_abs": math.nan}
    t = np.asarray(true, np.float64)[sel]
    d = np.asarray(mean, np.float64)[sel] - t
    inside = (t >= np.asarray(lo)[sel] - 1e-6) & (t <= np.asarray(hi)[sel] + 1e-6)
    return {"rmse": float(np.sqrt(np.mean(d ** 2))), "mean_abs": float(np.mean(np.abs(d))),
            "coverage": float(np.mean(inside))}


def posterior_interval_error(part: AlbedoPosterior, true, visible) -> dict:
    """Errors of one part's posterior against the truth, with both kinds of coverage.

    Parameters
    ----------
    part : AlbedoPosterior
    true : (n, 3) float array
    visible : (n,) bool

    Returns
    -------
    dict
        :func:`interval_error`'s ``rmse``, ``mean_abs`` and ``coverage`` (of the
        part's own intervals: predictive when ``part.predictive``), plus
        ``coverage_coefficients`` (coefficient-only intervals),
        ``coverage_predictive`` (None when the model has no residual variance)
        and ``predictive``.
    """
    out = interval_error(part.mean, part.lo, part.hi, true, visible)
    only = part.coefficient_only()
    coef = interval_error(only.mean, only.lo, only.hi, true, visible)["coverage"]
    out.update(coverage_coefficients=coef,
               coverage_predictive=out["coverage"] if part.predictive else None,
               predictive=bool(part.predictive))
    return out


def _rows_of(part: PCAPart, vertices: np.ndarray) -> PCAPart:
    """Restrict a part to the rows of some vertices (scoring needs no other; not orthonormal)."""
    rows = (3 * np.flatnonzero(vertices)[:, None] + np.arange(3)).ravel()
    residual = None if part.residual_variance is None else part.residual_variance[rows]
    return PCAPart(part.mean[rows], part.basis[rows], part.variance, part.noise_variance,
                   residual)


def albedo_score(model: MorphableModel, samples: np.ndarray, layout: ParamLayout,
                 true_diffuse: np.ndarray, visible: np.ndarray, *,
                 level: float = 0.9, colour: str = "linear") -> AlbedoScore:
    """Score coefficient samples against the true per-vertex diffuse albedo.

    Parameters
    ----------
    model : MorphableModel
    samples : (S, d) float array
        Parameter vectors (``layout``), e.g. pooled stage-2 samples after burn-in.
    layout : ParamLayout
    true_diffuse : (n, 3) float array
    visible : (n,) bool
        Vertices scored (those seen in the true view).
    level : float
        Central interval probability (0.9: 5 % / 95 %).
    colour : {"linear", "srgb"}
        The model's colour space in the fit; ``"srgb"`` scores the decoded samples
        (:func:`mcmcfit.outputs.albedo_decoding.decoded_albedo_posterior`) against
        the linear truth.

    Returns
    -------
    AlbedoScore
        ``coverage`` is predictive when the model has a residual variance.
    """
    sel = np.asarray(visible, bool)
    summarise = decoded_albedo_posterior if colour == "srgb" else albedo_posterior
    post = summarise(_rows_of(model.diffuse, sel),
                     np.asarray(samples)[:, albedo_columns(layout)], level=level)
    err = posterior_interval_error(post, np.asarray(true_diffuse)[sel], np.ones(sel.sum(), bool))
    n_samples = int(np.asarray(samples).shape[0])
    return AlbedoScore(err["rmse"], err["coverage"], float(level), n_samples,
                       err["coverage_coefficients"], err["predictive"])
