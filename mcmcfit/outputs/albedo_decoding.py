"""Posterior albedo of a model whose colour is an sRGB texture, reported in linear albedo.

A BFM-2017-like model (:func:`albedo_model.io.colour_space.model_colour_space`
``"srgb"``) is fitted in its own encoded space, where its colour is linear in
the coefficients. What the fit reports is linear albedo, so every summary is
taken over the **decoded** instances: each coefficient sample ``c_s`` gives
the encoded instance ``mu + W c_s``, decoded once
(:func:`albedo_model.io.colour_space.decode_texture`), and the mean, standard
deviation and central interval are those of the decoded samples. The decoding
is not linear, so the mean is not the decoded mean instance (the exact linear
formulas of :mod:`mcmcfit.outputs.posterior` do not apply). With a residual
variance (stated in the model's encoded space) the predictive std and interval
are those of ``decode(mu + W c_s + e)``, ``e ~ N(0, diag(r))``, by the same
Monte Carlo as the linear path; the mean stays the coefficient samples' one,
and ``residual_std`` is the residual sd carried to linear units to first order
(times the decoding's slope at the model mean).

:func:`model_colour_record` is the ``model`` record of ``summary.json``.

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.io.colour_space`,
:mod:`albedo_model.pca` and :mod:`mcmcfit.outputs.posterior`.
"""

from __future__ import annotations

import math

import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.colour_space import ColourSpace, decode_texture
from albedo_model.pca import PCAPart
from mcmcfit.outputs.posterior import BLOCK_ELEMENTS, AlbedoPosterior, row_quantiles

__all__ = ["COLOUR_HANDLING", "decoded_albedo_posterior", "model_colour_record"]

#: One line per colour space: how the fit compared the model with the photograph and
#: what it reports (``summary.json`` ``model.colour_handling``).
COLOUR_HANDLING = {
    "linear": "model colour is linear albedo: the render is compared with the photograph "
              "linearised with the pure power 2.2; albedo reported as sampled (linear sRGB)",
    "srgb": "model colour is a gamma-encoded sRGB texture: the render (model colour x "
            "shading) is compared with the photograph's encoded values, as the reference "
            "does; albedo samples decoded once to linear sRGB (IEC 61966-2-1) for every "
            "reported map and summary",
}


def model_colour_record(space: ColourSpace) -> dict:
    """Return ``summary.json``'s ``model`` record for a fit in colour space ``space``.

    Returns
    -------
    dict
        ``colour_space`` (``"linear"`` or ``"srgb"``), ``colour_space_source``
        (``"override"``, ``"model metadata"``, ...), ``colour_space_label`` and
        ``colour_handling`` (:data:`COLOUR_HANDLING`).
    """
    return {"colour_space": space.value, "colour_space_source": space.source,
            "colour_space_label": space.label, "colour_handling": COLOUR_HANDLING[space.value]}


def _moments(x: np.ndarray, q: list[float]) -> tuple[np.ndarray, ...]:
    """Mean, std and the ``q`` quantiles of each row of ``x`` (rows, draws)."""
    return (x.mean(axis=1), x.std(axis=1), *row_quantiles(x, q))


def decoded_albedo_posterior(part: PCAPart, coefficients: np.ndarray, *, level: float = 0.9,
                             predictive: bool = True, rng: np.random.Generator | None = None,
                             min_draws: int = 1000, block_rows: int = 8192) -> AlbedoPosterior:
    """Posterior (predictive) summaries of the decoded instances of an sRGB-texture part.

    Parameters
    ----------
    part : PCAPart
        Colour part of dimension 3n whose instances are encoded sRGB values.
    coefficients : (S, j) float array
        Posterior samples of the part's coefficients (j <= rank).
    level : float
        Probability of the central interval.
    predictive : bool
        Add the part's residual variance when it has one (default).
    rng : numpy.random.Generator, optional
        Residual draws (default: seed 0).
    min_draws : int
        Least number of Monte Carlo draws per row for the predictive summaries.
    block_rows : int
        Most rows of the data vector decoded at once.

    Returns
    -------
    AlbedoPosterior
        (n, 3) float32 linear sRGB: mean, std and interval of the decoded samples.
    """
    c = np.asarray(coefficients, np.float64)
    if c.ndim != 2 or c.shape[0] < 1 or c.shape[1] > part.rank:
        raise InputError(f"coefficient samples must be (S, j) with S >= 1 and j <= "
                         f"{part.rank}, got shape {c.shape}")
    if not 0 < level < 1:
        raise InputError(f"level must be in (0, 1), got {level}")
    w = part.scaled_basis[:, :c.shape[1]].astype(np.float64)
    base, ct = part.mean.astype(np.float64), np.ascontiguousarray(c.T)
    residual = part.residual_variance if predictive else None
    reps = 1 if residual is None else max(1, math.ceil(min_draws / c.shape[0]))
    rows = max(1, min(block_rows, BLOCK_ELEMENTS // (reps * c.shape[0])))
    q = [(1 - level) / 2, 1 - (1 - level) / 2]
    coef = np.empty((4, part.dim))
    pred = np.empty((3, part.dim)) if residual is not None else None
    rng = np.random.default_rng(0) if rng is None else rng
    for start in range(0, part.dim, rows):
        sl = slice(start, start + rows)
        x = base[sl, None] + w[sl] @ ct                       # (rows, S), encoded
        coef[:, sl] = _moments(decode_texture(x), q)
        if pred is not None:
            draws = rng.standard_normal((x.shape[0], x.shape[1], reps), dtype=np.float32)
            draws *= np.sqrt(residual[sl].astype(np.float64))[:, None, None].astype(np.float32)
            draws += x[:, :, None]
            pred[:, sl] = _moments(decode_texture(draws.reshape(x.shape[0], -1)), q)[1:]
    mean, std, lo, hi = (_f32(a) for a in coef)
    if pred is None:
        return AlbedoPosterior(mean, std, lo, hi, float(level))
    return AlbedoPosterior(mean, _f32(pred[0]), _f32(pred[1]), _f32(pred[2]), float(level),
                           coef_std=std, coef_lo=lo, coef_hi=hi,
                           residual_std=_f32(_linear_residual_std(part.mean, residual)))


def _f32(a: np.ndarray) -> np.ndarray:
    """Return the (3n,) values as (n, 3) float32."""
    return a.reshape(-1, 3).astype(np.float32)


def _linear_residual_std(mean: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """Carry the encoded residual sd carried to linear units by the decoding's slope at the mean."""
    m, h = np.asarray(mean, np.float64), 1e-4
    slope = (decode_texture(m + h) - decode_texture(m - h)) / (2 * h)
    return slope * np.sqrt(np.asarray(residual, np.float64))
