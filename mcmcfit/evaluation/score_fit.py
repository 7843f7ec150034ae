"""Score one fit's result folder against its case's truth: one row of the evaluation.

:func:`score_fit` reads ``posterior.npz`` (linear sRGB albedo whatever the
model's colour space: a fit of an sRGB-texture model reports decoded albedo)
and ``summary.json`` of a result folder, the true maps of the case, and the
model (its mean, decoded when its colour is an sRGB texture), and returns
the scores of :func:`mcmcfit.evaluation.scores.albedo_scores` for the
diffuse and (when both have one) specular albedo, with the fit's R-hat,
ESS, convergence verdict, wall time, seed, model hash and version, and the
case's projection floor, and the accuracy at each of the fit's convergence
checks (:mod:`mcmcfit.evaluation.checkpoints`).

This module imports :mod:`albedo_model` (colour space, regions) and
:mod:`mcmcfit.evaluation` (checkpoints, scores).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mcmcfit.evaluation.checkpoints import checkpoint_scores
from mcmcfit.evaluation.scores import albedo_scores

__all__ = ["model_mean_linear", "score_fit"]


def model_mean_linear(model, part: str, colour: str) -> np.ndarray | None:
    """Return the mean of ``model``'s ``part`` ("diffuse"/"specular") as linear (n, 3) values."""
    p = getattr(model, part)
    if p is None:
        return None
    mean = np.asarray(p.mean, np.float64).reshape(-1, 3)
    if colour == "srgb":
        from albedo_model.io.colour_space import decode_texture

        mean = decode_texture(mean)
    return mean


def _fit_record(summary: dict) -> dict:
    conv = summary.get("convergence") or {}
    timings = summary.get("timings") or {}
    model = summary.get("model") or {}
    return {"converged": summary.get("converged"), "max_rhat": conv.get("max_rhat"),
            "min_ess_bulk": conv.get("min_ess_bulk"), "min_ess_tail": conv.get("min_ess_tail"),
            "wall_s": timings.get("total_s"), "seed": summary.get("seed"),
            "model_sha256": summary.get("model_sha256"), "version": summary.get("version"),
            "fit_colour_space": model.get("colour_space"),
            "checks": (summary.get("stopping") or {}).get("checks", [])}


def score_fit(fit_dir: Path, truth_file: Path, model, colour: str,
              regions: dict | None = None) -> dict:
    """Scores of one fit (see the module docstring).

    Parameters
    ----------
    fit_dir : Path
        A complete result folder (``posterior.npz``, ``summary.json``).
    truth_file : Path
        The case's ``.npz``: ``diffuse``, ``specular``, ``visible``.
    model : MorphableModel
        The model fitted.
    colour : {"linear", "srgb"}
        Its colour space (the model mean is decoded for ``"srgb"``).
    regions : dict of str to (n,) bool, optional
        Face regions for the per-region errors.

    Returns
    -------
    dict
        ``diffuse`` and ``specular`` (or None) scores, and the fit's record
        (``converged``, ``max_rhat``, ``min_ess_bulk``, ``min_ess_tail``,
        ``wall_s``, ``seed``, ``model_sha256``, ``version``, ``checks``), and
        ``checkpoints``: the diffuse MSE and 90 % coverage at each convergence
        check (:func:`mcmcfit.evaluation.checkpoints.checkpoint_scores`).
    """
    fit_dir = Path(fit_dir)
    summary = json.loads((fit_dir / "summary.json").read_text(encoding="utf-8"))
    truth = np.load(truth_file)
    visible = np.asarray(truth["visible"], bool)
    out = {"diffuse": None, "specular": None, **_fit_record(summary)}
    with np.load(fit_dir / "posterior.npz") as post:
        for part in ("diffuse", "specular"):
            mean_key = f"{part}_mean"
            model_mean = model_mean_linear(model, part, colour)
            if mean_key not in post or model_mean is None:
                continue
            std = post.get(f"{part}_std")
            out[part] = albedo_scores(post[mean_key], std, truth[part], visible, model_mean,
                                      regions=regions if part == "diffuse" else None)
    out["checkpoints"] = checkpoint_scores(fit_dir, summary, model, truth["diffuse"], visible,
                                           colour)
    return out
