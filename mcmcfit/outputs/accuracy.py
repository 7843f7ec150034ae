"""Scores of a fit against a known truth: pose angle error, albedo RMSE and interval coverage.

This module imports :mod:`albedo_model` (camera, model, params),
:mod:`mcmcfit.outputs.posterior` and :mod:`mcmcfit.sampling.param_vector`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from albedo_model.camera import euler_rotation
from albedo_model.model import MorphableModel
from albedo_model.params import Pose
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.outputs.posterior import albedo_posterior

__all__ = ["AlbedoScore", "albedo_score", "albedo_columns", "interval_error", "pose_error_deg"]


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
        Fraction of (vertex, channel) values inside the central interval.
    level : float
        Probability of that interval.
    n_samples : int
    """

    rmse: float
    coverage: float
    level: float
    n_samples: int


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


def albedo_score(model: MorphableModel, samples: np.ndarray, layout: ParamLayout,
                 true_diffuse: np.ndarray, visible: np.ndarray, *,
                 level: float = 0.9) -> AlbedoScore:
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
    """
    post = albedo_posterior(model.diffuse, np.asarray(samples)[:, albedo_columns(layout)],
                            level=level)
    err = interval_error(post.mean, post.lo, post.hi, true_diffuse, visible)
    n_samples = int(np.asarray(samples).shape[0])
    return AlbedoScore(err["rmse"], err["coverage"], float(level), n_samples)
