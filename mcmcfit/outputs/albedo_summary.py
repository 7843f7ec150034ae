"""Posterior per-vertex diffuse and specular albedo of a fit, and its ``posterior.npz``.

The posterior is summarised from the pooled stage-2 samples of the shared
albedo coefficients after the burn-in (``config.burn_fraction``); a fit without
an image stage summarises its best sample (zero width).

This module imports :mod:`albedo_model.model`, :mod:`mcmcfit.fitting.result` and
:mod:`mcmcfit.outputs.posterior`.
"""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np

from albedo_model.model import MorphableModel
from mcmcfit.fitting.result import FitResult
from mcmcfit.outputs.posterior import AlbedoPosterior, albedo_posterior

__all__ = ["PosteriorAlbedo", "albedo_coefficient_samples", "posterior_albedo",
           "write_posterior_npz"]


class PosteriorAlbedo(NamedTuple):
    """Posterior albedo of one fit.

    Attributes
    ----------
    diffuse : AlbedoPosterior
    specular : AlbedoPosterior or None
        None when the model has no specular part.
    visible : (n,) bool
        Vertices seen in the fitted view (best sample).
    n_samples : int
        Coefficient samples summarised.
    """

    diffuse: AlbedoPosterior
    specular: AlbedoPosterior | None
    visible: np.ndarray
    n_samples: int


def albedo_coefficient_samples(result: FitResult) -> np.ndarray:
    """(S, j) pooled stage-2 albedo coefficients after the burn-in (best sample if none)."""
    sl = result.layout.slice("albedo")
    pooled = result.get_chain(2, flat=True, discard=result.config.burn_fraction)
    if pooled.shape[0] == 0:
        return np.asarray(result.best.params.momo.albedo, np.float64)[None, :]
    return pooled[:, sl]


def posterior_albedo(result: FitResult, model: MorphableModel, visible: np.ndarray, *,
                     level: float = 0.9) -> PosteriorAlbedo:
    """Summaries of the diffuse and specular albedo instances over the posterior samples.

    Parameters
    ----------
    result : FitResult
    model : MorphableModel
    visible : (n,) bool
        Vertices visible in the fitted view (:func:`mcmcfit.outputs.posterior.visible_vertices`).
    level : float
        Probability of the central credible interval.
    """
    coef = albedo_coefficient_samples(result)
    diffuse = albedo_posterior(model.diffuse, coef[:, :model.diffuse.rank], level=level)
    specular = None
    if model.specular is not None:
        if model.shared_albedo:
            spec_coef = coef[:, :model.specular.rank]
        else:  # independent specular coefficients are not sampled: the mean instance
            spec_coef = np.zeros((1, 0))
        specular = albedo_posterior(model.specular, spec_coef, level=level)
    return PosteriorAlbedo(diffuse, specular, np.asarray(visible, bool), int(coef.shape[0]))


def write_posterior_npz(path: str | os.PathLike, post: PosteriorAlbedo) -> None:
    """Write ``posterior.npz``: ``{diffuse,specular}_{mean,std,lo,hi}`` (n, 3) and ``visible`` (n,).

    Specular arrays are absent for models without a specular part. ``level``
    holds the interval probability (0.9: ``lo``/``hi`` are the 5 % / 95 % quantiles).
    """
    arrays: dict[str, np.ndarray] = {"visible": post.visible,
                                     "level": np.float64(post.diffuse.level)}
    for name, part in (("diffuse", post.diffuse), ("specular", post.specular)):
        if part is None:
            continue
        for field in ("mean", "std", "lo", "hi"):
            arrays[f"{name}_{field}"] = np.asarray(getattr(part, field), np.float32)
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)
