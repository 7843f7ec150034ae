"""``mcmcfit bench mixing``: effective samples per second, the new default against the reference.

What a user gets from a sampler is effective samples of the quantities they
read, per second of waiting. One run fits a synthetic case twice, both with
the same chains, steps and posterior:

* **default** -- the default (Gaussian) sampler: the climb to the mode, the
  pixel region and noise model measured there, moves from the posterior's
  Laplace approximation and the exact albedo and SH-light conditionals,
  step sizes adapted in warm-up; its measured noise model is then fixed for
* **reference** -- the reference's random-walk schedule (Schönborn et al. 2017:
  the multi-scale walks of every block, all coefficients moved at once, the
  SH solver, no conditionals, no adaptation) on the same posterior (the same
  preparation, ``sampler="reference"``), started at the mode.

For each it reports, over the monitored quantities of
:func:`mcmcfit.sampling.convergence.monitored_series` (log densities, moving
parameters, regions' mean albedo), the minimum and median bulk-ESS of the kept
draws per second of kept-draw wall time (chains run in parallel, so the wall
time is the slowest chain's), and the ratio default / reference; with the
stop rule on, the default's time to a converged posterior. Cases: the demo
(seed 0) and a harder one (yaw 40 deg, a strong side light).

This module imports :mod:`albedo_model.model`, :mod:`mcmcfit.fitting` (config,
fit, result), :mod:`mcmcfit.jobs.synthetic_case`, :mod:`mcmcfit.outputs.accuracy`
and :mod:`mcmcfit.sampling` (convergence, derived, diagnostics).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from albedo_model.model import MorphableModel
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.fit import fit
from mcmcfit.fitting.result import FitResult
from mcmcfit.jobs.synthetic_case import synthetic_case
from mcmcfit.outputs.accuracy import albedo_score
from mcmcfit.sampling.convergence import monitored_series
from mcmcfit.sampling.derived import region_albedo_basis
from mcmcfit.sampling.diagnostics import series_table

__all__ = ["CASES", "mixing_figures", "reference_config", "run_mixing_bench"]

#: name -> keyword arguments of :func:`~mcmcfit.jobs.synthetic_case.synthetic_case`.
CASES = {"demo": {"seed": 0}, "yaw40-side-light": {"seed": 1, "yaw_deg": 40.0,
                                                   "side_light": True}}


def reference_config(base: FitConfig, noise: dict) -> FitConfig:
    """Return the reference's random-walk schedule on the posterior of ``noise`` (a measured noise model)."""
    return base.replace(sampler="reference", noise="fixed", sigma_px=float(noise["sigma"]),
                        temperature=max(1.0, float(noise["temperature"])), albedo_weight=0.0,
                        light_conditional_weight=0.0, adapt=False, block_size=None,
                        specular_weight=0.0, stage1_shape_weight=0.0,
                        stop_when_converged=False)


def mixing_figures(result: FitResult, model: MorphableModel, case) -> dict:
    """ESS per second of the kept draws, accuracy, and the stop record of one fit."""
    recs = result.records(2)
    series = monitored_series(recs, result.layout, region_albedo_basis(model))
    table = series_table({k: v for k, v in series.items() if v.shape[1] >= 8})
    ess = np.array([d.ess_bulk for d in table.values()], np.float64)
    wall = max(r.seconds for r in recs)
    worst = min(table.items(), key=lambda kv: kv[1].ess_bulk)[0] if table else ""
    samples = np.concatenate([r.samples for r in recs])
    score = albedo_score(model, samples, result.layout, case.diffuse, case.visible)
    return {"kept_steps": int(recs[0].steps), "kept_wall_s": float(wall),
            "total_s": float(result.timings["total_s"]),
            "min_ess_bulk": float(np.nanmin(ess)), "median_ess_bulk": float(np.nanmedian(ess)),
            "min_ess_per_s": float(np.nanmin(ess) / wall),
            "median_ess_per_s": float(np.nanmedian(ess) / wall), "worst": worst,
            "max_rhat": float(result.convergence.get("max_rhat", math.nan)),
            "converged": bool(result.convergence.get("converged", False)),
            "rmse": float(score.rmse), "coverage": float(score.coverage),
            "noise": dict(result.noise), "stopping": dict(result.stopping)}


def run_mixing_bench(model: MorphableModel, *, config: FitConfig | None = None, seed: int = 0,
                     cases: tuple[str, ...] = tuple(CASES), size: int = 250,
                     progress: Callable | None = None) -> dict:
    """Fit each case with the default and the reference schedule; return the figures.

    Parameters
    ----------
    model : MorphableModel
    config : FitConfig, optional
        The default schedule's settings (the stop rule is switched off for the
        ESS comparison, so both run ``steps`` kept steps).
    seed : int
        Seed of the fits.
    cases : names in :data:`CASES`
    size : int
        Image size in pixels.
    progress : callable ``(case, schedule)``, optional
        Called before each fit.

    Returns
    -------
    dict case -> {"default": {...}, "reference": {...}, "ratio_min_ess_per_s": float,
    "ratio_median_ess_per_s": float}
    """
    base = (config or FitConfig()).replace(stop_when_converged=False)
    out = {}
    for name in cases:
        case = synthetic_case(model, size=size, **CASES[name])
        figures = {}
        for label in ("default", "reference"):
            if progress is not None:
                progress(name, label)
            cfg = base if label == "default" else reference_config(base,
                                                                    figures["default"]["noise"])
            result = fit(case.image, case.landmarks, model, config=cfg, seed=seed)
            figures[label] = mixing_figures(result, model, case)
        d, r = figures["default"], figures["reference"]
        figures["ratio_min_ess_per_s"] = d["min_ess_per_s"] / max(r["min_ess_per_s"], 1e-12)
        figures["ratio_median_ess_per_s"] = d["median_ess_per_s"] / max(
            r["median_ess_per_s"], 1e-12)
        out[name] = figures
    return out
