"""``summary.json`` of a fit: provenance, schedule, timings, acceptance, diagnostics, errors.

This module imports only :mod:`mcmcfit.fitting.result` (and numpy, the standard library).
"""

from __future__ import annotations

import math
import platform
from importlib.metadata import PackageNotFoundError, version

import numpy as np

from mcmcfit.fitting.result import FitResult

__all__ = ["SUMMARY_FORMAT", "landmark_errors", "build_summary", "json_safe", "software_versions"]

#: Identifies the layout of ``summary.json``; bumped when fields change meaning.
SUMMARY_FORMAT = "mcmcfit-fit-summary/2"


def _mcmcfit_version() -> str:
    """Return the installed mcmcfit version (``mcmcfit.__version__``, without the facade)."""
    try:
        return version("mcmcfit")
    except PackageNotFoundError:  # running from a source tree without install
        return "0.0.0+unknown"


def software_versions() -> dict[str, str]:
    """Return the versions of mcmcfit and the libraries that shape its numbers."""
    out = {"mcmcfit": _mcmcfit_version(), "python": platform.python_version()}
    for pkg in ("numpy", "jax", "jaxlib", "embreex", "emcee", "arviz"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "absent"
    return out


def landmark_errors(clicked: dict[str, np.ndarray], names: list[str], projected: np.ndarray
                    ) -> dict:
    """Pixel distances between target landmarks and the fit's projections.

    Parameters
    ----------
    clicked : mapping name -> (2,) target pixels
    names : list of str, ``projected``'s rows
    projected : (k, 2) pixels of the fitted model's landmarks

    Returns
    -------
    dict
        ``rmse_px`` (root mean square distance over the landmarks with a finite
        projection; NaN without any), ``per_landmark_px`` {name: distance}.
    """
    per = {}
    for name, p in zip(names, np.asarray(projected, np.float64).reshape(-1, 2)):
        if name in clicked and np.all(np.isfinite(p)):
            per[name] = float(np.linalg.norm(p - clicked[name]))
    d = np.array(list(per.values()))
    rmse = float(np.sqrt(np.mean(d ** 2))) if d.size else math.nan
    return {"rmse_px": rmse, "per_landmark_px": per}


def _stage_diag(result: FitResult) -> dict:
    d = result.diagnostics.get("stage2") or result.diagnostics.get("stage1") or {}
    return d


def build_summary(result: FitResult, *, model_sha256: str, model_uri: str, inputs: dict,
                  landmark_err: dict | None, albedo: dict, files: list[str],
                  truth_error: dict | None = None, extra_timings: dict | None = None,
                  model: dict | None = None) -> dict:
    """Build the ``summary.json`` dict (JSON-safe: NaN and infinities become null).

    Fields: ``format``, ``software`` (versions), ``version`` (mcmcfit), ``seed``,
    ``model_sha256``, ``model_uri``, ``inputs``, ``steps`` (``landmark``,
    ``image`` per chain, ``chains``, ``thin``, ``stage1_sampler``), ``timings``
    (seconds: ``setup_s``, ``stage1_s``, ``stage2_s`` summed over chains,
    ``total_s`` wall time of the fit, ``outputs_s``, steps per second),
    ``acceptance`` / ``acceptance_stage1`` (per proposal: counts by filter and
    ``rate``), ``acceptance_rate`` (per chain), ``ess`` (bulk-ESS), ``ess_tail``
    and ``rhat`` (rank-normalised split R-hat) per monitored quantity of the last
    stage run (log densities, every sampled column that moves, the regions' mean
    albedo ``albedo_mean.<region>.<r|g|b>`` when computed; ArviZ's estimators,
    :mod:`mcmcfit.sampling.diagnostics`), ``converged`` and ``convergence`` (the
    image stage's verdict), ``noise_model`` and ``stopping`` (of the fit, when it
    records them), ``diagnostics`` (both stages: ``ess_bulk``, ``ess_tail``,
    ``rhat`` per quantity), ``landmark_rmse_px`` (best sample) and ``landmark_errors_px``,
    ``landmarks`` (``used``, ``unknown``), ``best`` / ``best_posterior`` log
    densities, ``albedo`` (colour space, interval, sample count, visibility;
    ``predictive``, ``interval_kind``, ``residual_variance`` per part with
    ``present`` and ``rms_rgb``, the coefficient-only and predictive mean std:
    :func:`mcmcfit.outputs.albedo_summary.albedo_interval_fields`),
    ``model`` (the model's colour space as the fit read it: ``colour_space``
    "linear" or "srgb", ``colour_space_source``, ``colour_space_label``,
    ``colour_handling``: :func:`mcmcfit.outputs.albedo_decoding.model_colour_record`;
    when given), ``truth`` (synthetic cases only), ``config`` and ``files`` (the result folder's
    files, among them ``chain.h5`` and ``posterior.nc``, the ArviZ ``InferenceData``).
    """
    __version__ = _mcmcfit_version()
    base = result.summary()
    cfg = result.config
    diag = _stage_diag(result)
    timings = dict(result.timings)
    timings.update(extra_timings or {})
    out = {
        "format": SUMMARY_FORMAT,
        "version": __version__,
        "software": software_versions(),
        "seed": int(result.seed),
        "model_sha256": model_sha256,
        "model_uri": model_uri,
        **({"model": model} if model is not None else {}),
        "inputs": inputs,
        "steps": {"landmark": cfg.landmark_steps, "image": cfg.steps, "chains": cfg.chains,
                  "thin": cfg.thin, "stage1_sampler": cfg.stage1},
        "timings": timings,
        "acceptance": base["acceptance"],
        "acceptance_stage1": base["acceptance_stage1"],
        "acceptance_rate": base["acceptance_rate"],
        "ess": {k: v.ess_bulk for k, v in diag.items()},
        "ess_tail": {k: v.ess_tail for k, v in diag.items()},
        "rhat": {k: v.rhat for k, v in diag.items()},
        "converged": bool(result.convergence.get("converged", False)),
        "convergence": result.convergence,
        "noise_model": base.get("noise_model") or {},
        "stopping": base.get("stopping") or {},
        "diagnostics": base["diagnostics"],
        "landmark_rmse_px": None if landmark_err is None else landmark_err["rmse_px"],
        "landmark_errors_px": None if landmark_err is None else landmark_err["per_landmark_px"],
        "landmarks": {"used": list(result.landmarks_used),
                      "unknown": list(result.landmarks_unknown)},
        "best": base["best"],
        "best_posterior": base["best_posterior"],
        "albedo": albedo,
        "config": base["config"],
        "files": sorted(files),
    }
    if truth_error is not None:
        out["truth"] = truth_error
    return json_safe(out)


def json_safe(value):
    """Return a copy with NumPy scalars as Python numbers and non-finite floats as None."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    return value
