"""Errors of a posterior albedo against a known truth (synthetic cases, the demo).

This module imports numpy and :mod:`mcmcfit.outputs.accuracy` (the error measures).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mcmcfit.outputs.accuracy import posterior_interval_error

__all__ = ["Truth", "albedo_error"]


class Truth(NamedTuple):
    """Ground truth of a synthetic case.

    Attributes
    ----------
    diffuse, specular : (n, 3) float, linear sRGB
        True per-vertex albedo (``specular`` may be None).
    visible : (n,) bool
        Vertices visible in the true view; errors are taken over these.
    params : RenderParameter, optional
        The true scene (pose errors).
    """

    diffuse: np.ndarray
    specular: np.ndarray | None
    visible: np.ndarray
    params: object = None


def albedo_error(post, truth: Truth) -> dict:
    """RMSE and interval coverage of the posterior albedo on the truly visible vertices.

    Parameters
    ----------
    post : mcmcfit.outputs.albedo_summary.PosteriorAlbedo
    truth : Truth

    Returns
    -------
    dict
        ``diffuse`` (and ``specular``): ``rmse`` of the posterior mean over
        vertices and channels (linear sRGB), ``mean_abs``, and ``coverage``: the
        fraction of (vertex, channel) values inside the central interval
        (predictive when the model has a residual variance), with
        ``coverage_predictive`` (None without one), ``coverage_coefficients``
        and ``predictive`` (:func:`~mcmcfit.outputs.accuracy.posterior_interval_error`);
        ``interval`` (its probability), ``n_visible``; ``pose_error_deg`` when
        the truth has parameters (filled by the caller).
    """
    out = {"interval": float(post.diffuse.level), "n_visible": int(np.sum(truth.visible)),
           "diffuse": posterior_interval_error(post.diffuse, truth.diffuse, truth.visible)}
    if post.specular is not None and truth.specular is not None:
        out["specular"] = posterior_interval_error(post.specular, truth.specular, truth.visible)
    return out
