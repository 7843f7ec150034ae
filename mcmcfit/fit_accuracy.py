"""Scores of a fit against a known truth: pose angle error, albedo RMSE and interval coverage.

This module imports :mod:`albedo_model` and :mod:`mcmcfit` (posterior, parameter vectors).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from albedo_model.camera import euler_rotation
from albedo_model.model import MorphableModel
from albedo_model.params import Pose
from mcmcfit.param_vector import ParamLayout
from mcmcfit.posterior import albedo_posterior

__all__ = ["AlbedoScore", "albedo_score", "colour_columns", "pose_error_deg"]


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


def colour_columns(layout: ParamLayout) -> list[int]:
    """Column indices of the albedo coefficients ``color.0, color.1, ...`` in ``layout``."""
    out = []
    i = 0
    while f"color.{i}" in layout.names:
        out.append(layout.index(f"color.{i}"))
        i += 1
    return out


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
    cols = colour_columns(layout)
    post = albedo_posterior(model.diffuse, np.asarray(samples)[:, cols], level=level)
    vis = np.asarray(visible, bool)
    t = np.asarray(true_diffuse, np.float64)[vis]
    err = post.mean[vis].astype(np.float64) - t
    inside = (post.lo[vis] <= t + 1e-6) & (t - 1e-6 <= post.hi[vis])
    return AlbedoScore(float(np.sqrt(np.mean(err * err))), float(np.mean(inside)),
                       float(level), int(np.asarray(samples).shape[0]))
