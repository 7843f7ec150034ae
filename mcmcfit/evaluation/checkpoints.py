"""What a fit's accuracy cost in time: its albedo scored at each convergence check of its chains.

A fit checks convergence every few hundred kept steps and records each check's
kept steps and wall time (``summary.json`` ``stopping.checks``).
:func:`checkpoint_scores` re-reads the chains (``chain.h5``), pools every
chain's kept draws up to each check (after the fit's burn-in fraction), and
scores their posterior mean and 90 % intervals against the true diffuse albedo
the way the fit's own summary does (:func:`mcmcfit.outputs.accuracy.albedo_score`:
predictive intervals when the model has a residual variance, scaled as the
fit's ``posterior.npz`` says (``diffuse_residual_scale``, estimated once at
the end of the fit, :mod:`mcmcfit.outputs.residual_scale`); an sRGB-texture
model's draws decoded first). At most ``max_draws`` evenly spaced draws are
scored per check (interval ends from a few hundred draws move the coverage by
about a point; all draws of a long chain would take minutes per check).

This module imports :mod:`mcmcfit.outputs` (accuracy, residual_scale) and
:mod:`mcmcfit.sampling` (chain, chain_file).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mcmcfit.outputs.accuracy import albedo_score
from mcmcfit.outputs.residual_scale import scale_residual_variance
from mcmcfit.sampling.chain import stacked_samples
from mcmcfit.sampling.chain_file import read_chains_h5

__all__ = ["MAX_DRAWS", "checkpoint_scores"]

#: Draws scored per check at most.
MAX_DRAWS = 400


def checkpoint_scores(fit_dir: Path, summary: dict, model, true_diffuse: np.ndarray,
                      visible: np.ndarray, colour: str, *,
                      max_draws: int = MAX_DRAWS) -> list[dict]:
    """Score the diffuse albedo of the draws kept up to each convergence check of a fit.

    Parameters
    ----------
    fit_dir : Path
        The fit's result folder (``chain.h5``).
    summary : dict
        Its ``summary.json`` (``stopping.checks``, ``config.burn_fraction``).
    model : MorphableModel
        The model fitted.
    true_diffuse : (n, 3) float array
        True linear diffuse albedo per vertex.
    visible : (n,) bool
        Vertices scored.
    colour : {"linear", "srgb"}
        The model's colour space in the fit.
    max_draws : int

    Returns
    -------
    list of dict
        Per check: ``kept_steps``, ``seconds`` (wall time since the fit's start),
        ``mse`` (posterior mean, over the visible vertices and channels),
        ``coverage_90``, ``draws`` (pooled draws up to the check). Empty when
        the fit recorded no checks or no chain file.
    """
    checks = (summary.get("stopping") or {}).get("checks") or []
    path = Path(fit_dir) / "chain.h5"
    if not checks or not path.is_file():
        return []
    burn = float((summary.get("config") or {}).get("burn_fraction", 0.0) or 0.0)
    post = Path(fit_dir) / "posterior.npz"
    if post.is_file():
        with np.load(post) as z:
            if "diffuse_residual_scale" in z:
                model = scale_residual_variance(model, np.asarray(z["diffuse_residual_scale"]))
    chains, layout, _ = read_chains_h5(path)
    records = [c.stage2 for c in chains if c.stage2 is not None]
    out = []
    for check in checks:
        n = int(check["kept_steps"])
        samples = stacked_samples(records, layout.size, discard=burn, flat=True, before_step=n)
        if samples.shape[0] == 0:
            continue
        pick = np.unique(np.linspace(0, samples.shape[0] - 1,
                                     min(max_draws, samples.shape[0])).round().astype(int))
        score = albedo_score(model, samples[pick], layout, true_diffuse, visible, colour=colour)
        out.append({"kept_steps": n, "seconds": float(check["seconds"]),
                    "mse": float(score.rmse) ** 2, "coverage_90": float(score.coverage),
                    "draws": int(samples.shape[0])})
    return out
