"""The ``batch.jsonl`` fields of a finished image, from its result folder.

From ``summary.json`` (:func:`mcmcfit.outputs.summary.build_summary`): the
stage-2 acceptance rate over all proposals and chains, the landmark RMS error
of the best sample, timings; from ``posterior.npz``: the posterior-mean diffuse
(and specular) albedo averaged over the vertices visible in the fitted view,
linear sRGB, and the mean posterior standard deviation there.

This module imports NumPy and the standard library.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

__all__ = ["overall_acceptance", "albedo_digest", "finished_record", "record_from_folder"]


def overall_acceptance(acceptance: dict | None) -> float | None:
    """Return accepted / proposed summed over proposals (``summary["acceptance"]``).

    None when there are no proposals.
    """
    if not acceptance:
        return None
    proposed = sum(int(v.get("proposed", 0)) for v in acceptance.values())
    accepted = sum(int(v.get("accepted", 0)) for v in acceptance.values())
    return accepted / proposed if proposed else None


def albedo_digest(posterior_npz: str | os.PathLike) -> dict:
    """Mean posterior albedo over visible vertices, linear sRGB (empty dict if unreadable).

    Returns
    -------
    dict
        ``diffuse_mean_rgb`` (3 floats), ``diffuse_mean`` (their mean),
        ``diffuse_std_mean`` (mean posterior std), ``specular_mean_rgb`` when
        the model has specular albedo, ``n_visible``.
    """
    p = Path(posterior_npz)
    if not p.is_file():
        return {}
    with np.load(p) as z:
        visible = np.asarray(z["visible"], bool) if "visible" in z else None
        out: dict = {}
        for part in ("diffuse", "specular"):
            if f"{part}_mean" not in z:
                continue
            mean = np.asarray(z[f"{part}_mean"], np.float64)
            std = np.asarray(z[f"{part}_std"], np.float64)
            sel = visible if visible is not None and visible.any() else slice(None)
            rgb = mean[sel].mean(axis=0)
            out[f"{part}_mean_rgb"] = [float(v) for v in rgb]
            out[f"{part}_mean"] = float(rgb.mean())
            out[f"{part}_std_mean"] = float(std[sel].mean())
        out["n_visible"] = int(visible.sum()) if visible is not None else None
    return out


def _finite(x) -> float | None:
    return float(x) if isinstance(x, (int, float)) and math.isfinite(x) else None


def finished_record(summary: dict, folder: str | os.PathLike | None = None) -> dict:
    """Journal fields of a finished fit.

    Parameters
    ----------
    summary : dict
        The content of ``summary.json``.
    folder : path-like, optional
        The result folder (for ``posterior.npz``); default: none, no albedo digest.

    Returns
    -------
    dict
        ``acceptance``, ``acceptance_stage1``, ``landmark_rms_px`` (a joint fit:
        the mean over its photographs), ``fit_seconds``, ``albedo`` (see
        :func:`albedo_digest`), ``log_lik_img`` (best), ``model_sha256``,
        ``converged``, ``n_images`` (photographs fitted together).
    """
    timings = summary.get("timings") or {}
    best = summary.get("best") or {}
    images = summary.get("images") or []
    landmark = _finite(summary.get("landmark_rmse_px"))
    per_image = [v for v in (_finite(im.get("landmark_rmse_px")) for im in images)
                 if v is not None]
    if images and per_image:
        landmark = sum(per_image) / len(per_image)
    return {
        "acceptance": overall_acceptance(summary.get("acceptance")),
        "acceptance_stage1": overall_acceptance(summary.get("acceptance_stage1")),
        "landmark_rms_px": landmark,
        "fit_seconds": _finite(timings.get("total_s")),
        "log_lik_img": _finite(best.get("log_lik_img")),
        "model_sha256": summary.get("model_sha256"),
        "converged": summary.get("converged"),
        "n_images": len(images) or 1,
        "albedo": albedo_digest(Path(folder) / "posterior.npz") if folder is not None else {},
    }


def record_from_folder(folder: str | os.PathLike) -> dict:
    """:func:`finished_record` of a complete result folder (reads ``summary.json``)."""
    folder = Path(folder)
    summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    return finished_record(summary, folder)
