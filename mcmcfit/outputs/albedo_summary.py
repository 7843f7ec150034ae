"""Posterior per-vertex diffuse and specular albedo of a fit, and its ``posterior.npz``.

The posterior is summarised from the pooled stage-2 samples of the shared
albedo coefficients after the burn-in (``config.burn_fraction``); a fit without
an image stage summarises its best sample (zero width). When the model's albedo
parts carry a residual variance, the std and intervals are posterior
predictive (coefficients + what the model cannot represent; see
:mod:`mcmcfit.outputs.posterior`) and the coefficient-only ones are kept beside
them; otherwise they are coefficient-only and say so
(:func:`albedo_interval_fields`, for ``summary.json``). The diffuse residual
variance is first scaled to the photograph(s) (:func:`estimate_residual_scale`,
:mod:`mcmcfit.outputs.residual_scale`), which also gives a model without one
predictive intervals. A model whose colour
is an sRGB texture (the fit's resolved colour space,
:func:`albedo_model.io.colour_space.model_colour_space`) is summarised over its
decoded samples (:mod:`mcmcfit.outputs.albedo_decoding`): always linear albedo.

This module imports :mod:`albedo_model` (io.colour_space, model, params),
:mod:`mcmcfit.fitting.result` and :mod:`mcmcfit.outputs` (albedo_decoding,
posterior, residual_scale).
"""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np

from albedo_model.io.colour_space import model_colour_space
from albedo_model.model import MorphableModel
from albedo_model.params import RenderParameter
from mcmcfit.fitting.result import FitResult
from mcmcfit.outputs.albedo_decoding import decoded_albedo_posterior
from mcmcfit.outputs.posterior import AlbedoPosterior, albedo_posterior
from mcmcfit.outputs.residual_scale import (
    residual_evidence,
    residual_scale,
    scale_residual_variance,
)

__all__ = ["PosteriorAlbedo", "albedo_coefficient_samples", "albedo_interval_fields",
           "estimate_residual_scale", "posterior_albedo", "write_posterior_npz"]


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
    colour : {"linear", "srgb"}
        The model's colour space in the fit; ``"srgb"``: the summaries are of
        the decoded samples (linear albedo either way).
    residual_scale : dict or None
        How the diffuse residual variance was scaled to the photograph(s)
        (:func:`estimate_residual_scale`), None when it was not.
    """

    diffuse: AlbedoPosterior
    specular: AlbedoPosterior | None
    visible: np.ndarray
    n_samples: int
    colour: str = "linear"
    residual_scale: dict | None = None


#: Most posterior draws the per-vertex summaries read (evenly spaced through the pooled
#: chains): their Monte Carlo error is then far below the posterior sd, and the
#: quantiles of a 53k-vertex model take seconds, not minutes.
MAX_SUMMARY_DRAWS = 4000


def albedo_coefficient_samples(result: FitResult) -> np.ndarray:
    """(S, j) pooled stage-2 albedo coefficients after the burn-in (best sample if none).

    At most :data:`MAX_SUMMARY_DRAWS`, evenly spaced through each chain.
    """
    sl = result.layout.slice("albedo")
    chains = result.get_chain(2, discard=result.config.burn_fraction)  # (chains, draws, d)
    if chains.size == 0 or chains.shape[1] == 0:
        return np.asarray(result.best.params.momo.albedo, np.float64)[None, :]
    per_chain = max(1, MAX_SUMMARY_DRAWS // chains.shape[0])
    keep = np.unique(np.linspace(0, chains.shape[1] - 1, min(per_chain, chains.shape[1]))
                     .round().astype(int))
    return chains[:, keep][:, :, sl].reshape(-1, sl.stop - sl.start)


def estimate_residual_scale(result: FitResult, model: MorphableModel,
                            scenes: list[RenderParameter], images: list[np.ndarray], *,
                            exclude: list | None = None) -> dict:
    """Scale the model's diffuse residual variance to the photographs (:mod:`~mcmcfit.outputs.residual_scale`).

    Parameters
    ----------
    result : FitResult
    model : MorphableModel
    scenes : list of RenderParameter
        Each photograph's scene at the posterior mean.
    images : list of (H, W, 3) float
        The photographs as fitted (gamma-encoded).
    exclude : list of (H, W) bool or None, optional
        Per photograph, pixels left out (e.g. those a robust fit found occluded).

    Returns
    -------
    dict
        ``scale_rgb`` (3 floats, or None when not estimated), ``pairs`` (adjacent
        pixel pairs per photograph), ``base`` (``"leave-one-out"``: the model's
        residual variance is scaled; ``"unit"``: the model has none, the scale is
        the out-of-span variance) and ``note`` (why not, when not estimated).
    """
    base = "leave-one-out" if model.diffuse.residual_variance is not None else "unit"
    colour = model_colour_space(model, getattr(result.config, "model_colour", None)).value
    if colour == "srgb":
        return {"scale_rgb": None, "pairs": [], "base": base,
                "note": "not estimated: the model's colour is an sRGB texture"}
    mean_coef = albedo_coefficient_samples(result).mean(axis=0)
    diffuse = model.diffuse_instance(mean_coef[:model.diffuse.rank])
    specular = model.specular_instance(mean_coef if model.shared_albedo else None)
    exclude = list(exclude) if exclude is not None else [None] * len(images)
    evidence = [residual_evidence(model, p, im, diffuse, specular=specular,
                                  render_specular=bool(result.config.specular),
                                  seed=int(result.seed), exclude=ex,
                                  shadows=getattr(result.config, "effects", "sh") != "sh")
                for p, im, ex in zip(scenes, images, exclude)]
    scale = residual_scale(evidence)
    return {"scale_rgb": None if scale is None else [float(v) for v in scale],
            "pairs": [0 if e is None else e.pairs for e in evidence], "base": base,
            "note": "" if scale is not None else "not estimated: too few face pixels"}


def posterior_albedo(result: FitResult, model: MorphableModel, visible: np.ndarray, *,
                     level: float = 0.9, rng: np.random.Generator | None = None,
                     residual_scale: dict | None = None) -> PosteriorAlbedo:
    """Summaries of the diffuse and specular albedo instances over the posterior samples.

    Parameters
    ----------
    result : FitResult
    model : MorphableModel
    visible : (n,) bool
        Vertices visible in the fitted view (:func:`mcmcfit.outputs.posterior.visible_vertices`).
    level : float
        Probability of the central credible interval.
    rng : numpy.random.Generator, optional
        Residual draws of the predictive quantiles (default: seeded by the fit's seed).
    residual_scale : dict, optional
        Of :func:`estimate_residual_scale`: the diffuse residual variance is
        scaled per channel by its ``scale_rgb`` (set to it when the model has
        none) before the predictive summaries.

    Returns
    -------
    PosteriorAlbedo
        Predictive std and intervals for the parts with a residual variance
        (``part.predictive``), coefficient-only ones otherwise; linear albedo
        (decoded samples when the fit's colour space is ``"srgb"``).
    """
    if residual_scale is not None and residual_scale.get("scale_rgb") is not None:
        model = scale_residual_variance(model, np.asarray(residual_scale["scale_rgb"]))
    coef = albedo_coefficient_samples(result)
    rng = np.random.default_rng(int(result.seed)) if rng is None else rng
    colour = model_colour_space(model, getattr(result.config, "model_colour", None)).value
    summarise = decoded_albedo_posterior if colour == "srgb" else albedo_posterior
    diffuse = summarise(model.diffuse, coef[:, :model.diffuse.rank], level=level, rng=rng)
    specular = None
    if model.specular is not None:
        if model.shared_albedo:
            spec_coef = coef[:, :model.specular.rank]
        else:  # independent specular coefficients are not sampled: the mean instance
            spec_coef = np.zeros((1, 0))
        specular = summarise(model.specular, spec_coef, level=level, rng=rng)
    return PosteriorAlbedo(diffuse, specular, np.asarray(visible, bool), int(coef.shape[0]),
                           colour, residual_scale)


def _rms(a: np.ndarray, sel: np.ndarray | None = None) -> list[float]:
    """Root mean square per channel of (n, 3) values (over ``sel`` when given)."""
    x = np.asarray(a, np.float64)
    x = x if sel is None else x[sel]
    return [float(v) for v in np.sqrt(np.mean(x**2, axis=0))] if len(x) else [None] * 3


def albedo_interval_fields(post: PosteriorAlbedo) -> dict:
    """Describe the intervals of ``post`` for ``summary.json``'s ``albedo`` record.

    Returns
    -------
    dict
        ``predictive`` (bool: the diffuse std and intervals include the model's
        residual variance), ``interval_kind`` (a sentence), ``residual_variance``:
        per part (``diffuse``, ``specular``) ``{"present": bool, "rms_rgb": [r, g, b]
        or None}`` (root mean residual variance over all vertices, linear sRGB),
        ``residual_scale`` (:func:`estimate_residual_scale`'s record, None when
        not estimated), and the visible-vertex mean of the coefficient-only and predictive
        diffuse std (``diffuse_std_coefficients_visible_mean``,
        ``diffuse_std_predictive_visible_mean``, None when not predictive).
    """
    vis = np.asarray(post.visible, bool)
    residual = {}
    for name in ("diffuse", "specular"):
        part = getattr(post, name)
        if part is None:
            continue
        present = part.residual_std is not None
        residual[name] = {"present": present,
                          "rms_rgb": _rms(part.residual_std) if present else None}
    d = post.diffuse
    rs = post.residual_scale or {}
    scaled = rs.get("scale_rgb") is not None
    if d.predictive and scaled and rs.get("base") == "unit":
        kind = ("posterior predictive: coefficient samples + N(0, s2) per vertex and channel, "
                "s2 the out-of-span variance estimated from the photograph(s) (the model has "
                "no residual variance)")
    elif d.predictive and scaled:
        kind = ("posterior predictive: coefficient samples + N(0, s2 x the model's "
                "leave-one-out residual variance) per vertex and channel, s2 per channel "
                "estimated from the photograph(s)")
    elif d.predictive:
        kind = ("posterior predictive: coefficient samples + N(0, the model's leave-one-out "
                "residual variance) per vertex and channel")
    else:
        kind = ("coefficients only: the model has no residual variance (what it cannot "
                "represent is not in the intervals)")
    mean_vis = (lambda a: float(np.asarray(a, np.float64)[vis].mean()) if vis.any()
                else None)
    return {
        "predictive": bool(d.predictive), "interval_kind": kind, "residual_variance": residual,
        "residual_scale": post.residual_scale,
        "diffuse_std_coefficients_visible_mean": mean_vis(d.coefficient_only().std),
        "diffuse_std_predictive_visible_mean": mean_vis(d.std) if d.predictive else None,
    }


def write_posterior_npz(path: str | os.PathLike, post: PosteriorAlbedo) -> None:
    """Write ``posterior.npz``: ``{diffuse,specular}_{mean,std,lo,hi}`` (n, 3) and ``visible`` (n,).

    Specular arrays are absent for models without a specular part. ``level``
    holds the interval probability (0.9: ``lo``/``hi`` are the 5 % / 95 % quantiles).
    ``std``, ``lo`` and ``hi`` are predictive when ``{part}_predictive`` is True;
    ``{part}_coef_{std,lo,hi}`` are always the coefficient-only ones and
    ``{part}_residual_std`` (predictive parts only) is the residual sd added:
    the model's, times ``sqrt(diffuse_residual_scale)`` (per channel, when the
    scale was estimated from the photograph).
    """
    arrays: dict[str, np.ndarray] = {"visible": post.visible,
                                     "level": np.float64(post.diffuse.level)}
    for name, part in (("diffuse", post.diffuse), ("specular", post.specular)):
        if part is None:
            continue
        for field in ("mean", "std", "lo", "hi"):
            arrays[f"{name}_{field}"] = np.asarray(getattr(part, field), np.float32)
        only = part.coefficient_only()
        for field in ("std", "lo", "hi"):
            arrays[f"{name}_coef_{field}"] = np.asarray(getattr(only, field), np.float32)
        arrays[f"{name}_predictive"] = np.bool_(part.predictive)
        scale = (post.residual_scale or {}).get("scale_rgb")
        if name == "diffuse" and scale is not None:
            arrays["diffuse_residual_scale"] = np.asarray(scale, np.float64)
        if part.predictive:
            arrays[f"{name}_residual_std"] = np.asarray(part.residual_std, np.float32)
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)
