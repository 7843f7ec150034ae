"""Scores of an albedo estimate against the true albedo (arrays in, numbers out).

Every score is taken over the (vertex, channel) values of the rows given
(the vertices visible in the true view), in linear sRGB:

- :func:`mse`: mean squared error;
- :func:`gain_corrected_mse`: the error left after one least-squares global
  RGB gain (a per-channel scale of the whole estimate: what a colour error
  of the light or the camera would explain);
- :func:`coverage`: the fraction of true values inside the central interval
  ``mean +- z_p std`` at each nominal level ``p`` (the per-vertex posterior
  predictive sd; Gaussian intervals);
- :func:`interval_width`: the mean width ``2 z_p std`` of those intervals;
- :func:`region_mse`: the MSE inside each face region.

This module imports numpy and scipy only.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import norm

__all__ = ["LEVELS", "albedo_scores", "coverage", "gain_corrected_mse", "interval_width", "mse",
           "region_mse"]

#: Nominal levels of the central intervals scored.
LEVELS = (0.5, 0.8, 0.9, 0.95)


def _rows(values: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
    v = np.asarray(values, np.float64).reshape(-1, 3)
    return v if rows is None else v[np.asarray(rows, bool)]


def mse(estimate: np.ndarray, truth: np.ndarray, rows: np.ndarray | None = None) -> float:
    """Mean squared error over ``rows`` (all when None) and channels.

    Parameters
    ----------
    estimate, truth : (n, 3) float arrays
    rows : (n,) bool array, optional
    """
    e, t = _rows(estimate, rows), _rows(truth, rows)
    return float(np.mean((e - t) ** 2)) if e.size else float("nan")


def gain_corrected_mse(estimate: np.ndarray, truth: np.ndarray,
                       rows: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """MSE after the least-squares per-channel gain ``g = sum(e t) / sum(e e)``.

    Returns
    -------
    mse : float
    gain : (3,) float
    """
    e, t = _rows(estimate, rows), _rows(truth, rows)
    if not e.size:
        return float("nan"), np.ones(3)
    den = np.sum(e * e, axis=0)
    gain = np.where(den > 0, np.sum(e * t, axis=0) / np.where(den > 0, den, 1.0), 1.0)
    return float(np.mean((e * gain - t) ** 2)), gain


def coverage(mean: np.ndarray, std: np.ndarray, truth: np.ndarray,
             rows: np.ndarray | None = None, levels=LEVELS) -> dict[float, float]:
    """Fraction of true values inside ``mean +- z_p std`` for each nominal level ``p``.

    Parameters
    ----------
    mean, std, truth : (n, 3) float arrays
    rows : (n,) bool array, optional
    levels : sequence of float in (0, 1)

    Returns
    -------
    dict of float to float
    """
    m, s, t = _rows(mean, rows), _rows(std, rows), _rows(truth, rows)
    z = np.abs(t - m) / np.maximum(s, 1e-12)
    return {float(p): float(np.mean(z <= norm.ppf(0.5 + p / 2))) if z.size else float("nan")
            for p in levels}


def interval_width(std: np.ndarray, rows: np.ndarray | None = None, level: float = 0.9) -> float:
    """Mean width ``2 z_p std`` of the central intervals of level ``p``."""
    s = _rows(std, rows)
    return float(2.0 * norm.ppf(0.5 + level / 2) * np.mean(s)) if s.size else float("nan")


def region_mse(estimate: np.ndarray, truth: np.ndarray, rows: np.ndarray | None,
               regions: dict[str, np.ndarray]) -> dict[str, float]:
    """MSE inside each region (restricted to ``rows``); regions without a row are left out."""
    keep = np.ones(len(np.asarray(truth).reshape(-1, 3)), bool) if rows is None else rows
    out = {}
    for name, mask in regions.items():
        sel = np.asarray(mask, bool) & np.asarray(keep, bool)
        if sel.any():
            out[name] = mse(estimate, truth, sel)
    return out


def albedo_scores(mean: np.ndarray, std: np.ndarray | None, truth: np.ndarray,
                  rows: np.ndarray, model_mean: np.ndarray, *,
                  regions: dict[str, np.ndarray] | None = None, levels=LEVELS) -> dict:
    """All scores of one albedo part (see the module docstring).

    Parameters
    ----------
    mean : (n, 3) float
        Posterior mean.
    std : (n, 3) float or None
        Posterior (predictive) sd; None leaves the interval scores out.
    truth : (n, 3) float
    rows : (n,) bool
        Vertices visible in the true view.
    model_mean : (n, 3) float
        The model's mean (linear).
    regions : dict of str to (n,) bool, optional
    levels : sequence of float

    Returns
    -------
    dict
        ``mse``, ``mse_model_mean``, ``mse_gain`` and ``gain``, ``rmse``,
        ``coverage`` (level -> fraction, keys as strings), ``width_90``,
        ``regions`` (name -> MSE), ``n_rows``.
    """
    gain_mse, gain = gain_corrected_mse(mean, truth, rows)
    out = {"mse": mse(mean, truth, rows), "mse_model_mean": mse(model_mean, truth, rows),
           "mse_gain": gain_mse, "gain": [float(g) for g in gain],
           "n_rows": int(np.sum(rows))}
    out["rmse"] = float(np.sqrt(out["mse"]))
    if std is not None:
        out["coverage"] = {f"{p:g}": c for p, c in coverage(mean, std, truth, rows, levels).items()}
        out["width_90"] = interval_width(std, rows, 0.9)
    if regions:
        out["regions"] = region_mse(mean, truth, rows, regions)
    return out
