"""Write every output of one fit into a folder (the caller makes the folder atomic).

Files (see the README's "Using it" section):

==============================  ==========================================================
``posterior.npz``               ``diffuse_``/``specular_`` ``mean``, ``std``, ``lo``, ``hi``
                                (n, 3) linear sRGB (5 % / 95 %; posterior predictive when
                                ``<part>_predictive``), ``<part>_coef_{std,lo,hi}``
                                (coefficient-only), ``<part>_residual_std``, ``visible``
``best.rps``, ``mean.rps``      best sample (highest image likelihood) and posterior mean (V4)
``target.png``, ``fit.png``     the input, and the best fit rendered over it
``fit_landmarks.png``           target and fitted landmarks, fit, difference (figure)
``occlusion.png``               ``--foreground robust``: each face pixel's probability of being
                                an occluder at the posterior mean (figure;
                                :mod:`mcmcfit.outputs.occlusion`)
``albedo_<part>_<view>.png``    posterior-mean albedo, display-encoded, RGBA (view: ``fitted``
                                or ``frontal``; part: ``diffuse`` or ``specular``)
``uncertainty_<part>_<view>``   posterior std (mean over R, G, B) with a colour bar (figure):
``.png``                        coefficient-only, and predictive beside it when the model has
                                a residual variance
``traces.png``                  log densities and sampled parameters per step (figure)
``mesh.ply``                    mean shape with posterior-mean diffuse albedo (gamma 2.2)
``chain.h5``                    every chain (:meth:`FitResult.save_chain`)
``posterior.nc``                the image stage as an ArviZ ``InferenceData`` (posterior,
                                sample_stats, warm-up groups, observed_data; netCDF-4):
                                :mod:`mcmcfit.outputs.inference_data`
``config.json``                 the :class:`~mcmcfit.fitting.config.FitConfig`
``summary.json``                see :func:`mcmcfit.outputs.summary.build_summary`
``report.html``                 everything above on one page
==============================  ==========================================================

This module imports :mod:`albedo_model` (io.colour_space, io.image_io, io.mesh_export,
io.rps, render.renderer), :mod:`mcmcfit.fitting.result`, :mod:`mcmcfit.targets.landmarks`
and the other :mod:`mcmcfit.outputs` modules but accuracy and html_style
(:mod:`~mcmcfit.outputs.report` when the report is written).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from albedo_model.io.colour_space import model_colour_space
from albedo_model.io.image_io import write_png
from albedo_model.io.mesh_export import write_mesh
from albedo_model.io.rps import write_rps
from mcmcfit.fitting.problem import fit_renderer
from mcmcfit.fitting.result import FitResult
from mcmcfit.outputs.albedo_decoding import model_colour_record
from mcmcfit.outputs.albedo_summary import (
    albedo_interval_fields,
    estimate_residual_scale,
    posterior_albedo,
    write_posterior_npz,
)
from mcmcfit.outputs.figures import (
    save_landmark_figure,
    save_traces,
    save_uncertainty_map,
    uncertainty_scale,
)
from mcmcfit.outputs.inference_data import inference_data, write_posterior_nc
from mcmcfit.outputs.occlusion import face_probability, occlusion_record, save_occlusion_map
from mcmcfit.outputs.posterior import visible_vertices
from mcmcfit.outputs.summary import build_summary, landmark_errors, software_versions
from mcmcfit.outputs.truth import Truth, albedo_error
from mcmcfit.outputs.vertex_maps import encode_display, frontal_params, vertex_image
from mcmcfit.targets.landmarks import target_landmarks

__all__ = ["OUTPUT_FILES", "fit_inference_data", "write_fit_outputs"]

#: Files every result folder holds (specular pictures only for models with specular albedo).
OUTPUT_FILES = (
    "posterior.npz", "best.rps", "mean.rps", "target.png", "fit.png", "fit_landmarks.png",
    "albedo_diffuse_fitted.png", "albedo_diffuse_frontal.png",
    "uncertainty_diffuse_fitted.png", "uncertainty_diffuse_frontal.png",
    "traces.png", "mesh.ply", "chain.h5", "posterior.nc", "config.json", "summary.json",
    "report.html",
)

#: FitConfig fields of the likelihoods' noise model (``posterior.nc`` attrs, with the fitted
#: ``FitResult.noise`` when the fit has one).
_NOISE_FIELDS = ("noise", "sigma_px", "temperature", "likelihood", "trim_fraction", "background",
                 "foreground", "outlier_probability", "sigma_lm", "lm_hidden_probability")


def write_fit_outputs(folder: str | os.PathLike, result: FitResult, loaded, image: np.ndarray, *,
                      landmarks=None, face_box=None, inputs: dict | None = None,
                      truth: Truth | None = None) -> dict:
    """Write the outputs of ``result`` into ``folder`` and return the summary dict.

    Parameters
    ----------
    folder : path-like
        An existing (empty, temporary) folder.
    result : FitResult
    loaded : mcmcfit.jobs.fit_job.LoadedModel
        The fitted model with its file SHA-256 and URI.
    image : (H, W, 3) float in [0, 1]
        The target as fitted (gamma-encoded).
    landmarks : list of Landmark or mapping, optional
        The target landmarks (for the landmark error and figure).
    face_box : (x0, y0, x1, y1), optional
    inputs : dict, optional
        Recorded as ``summary["inputs"]``.
    truth : Truth, optional
        Ground truth of a synthetic case: the albedo error goes into the summary.

    Returns
    -------
    dict
        The content written to ``summary.json``.
    """
    t0 = time.perf_counter()
    out = Path(folder)
    model = loaded.model
    cfg = result.config
    best = result.best.params
    mean = result.mean_params if result.mean_params is not None else best
    # the fit's renderer settings (linear output), so that its compiled stages are reused
    renderer = fit_renderer(model, cfg, threads=cfg.threads)
    state = renderer.init_state(best)
    rendered = renderer.image(state)
    space = model_colour_space(model, cfg.model_colour)
    # an sRGB-texture model renders encoded values already (the space the fit compared in)
    shown = np.clip(rendered.image, 0.0, 1.0) if space.is_srgb else encode_display(rendered.image)
    fitted = rendered._replace(image=np.asarray(shown, np.float32))
    visible = visible_vertices(renderer, state)
    occlusion = face_probability(result, renderer, mean, image)
    occluded = None if occlusion is None else occlusion[1] & (occlusion[0] < 0.5)
    post = posterior_albedo(result, model, visible, residual_scale=estimate_residual_scale(
        result, model, [mean], [image], exclude=[occluded]))
    write_posterior_npz(out / "posterior.npz", post)
    write_rps(out / "best.rps", best)
    write_rps(out / "mean.rps", mean)

    target = np.clip(np.asarray(image, np.float64), 0.0, 1.0)
    write_png(out / "target.png", target)
    write_png(out / "fit.png", np.where(fitted.mask[..., None], fitted.image, target))
    if occlusion is not None:
        save_occlusion_map(out / "occlusion.png", *occlusion)

    clicked = target_landmarks(landmarks) if landmarks is not None else {}
    lm_err = None
    projected = None
    if result.landmarks_used:
        names, px, _ = renderer.landmarks(state, list(result.landmarks_used))
        lm_err = landmark_errors(clicked, names, px)
        projected = np.asarray(px)
    save_landmark_figure(out / "fit_landmarks.png", target, fitted.image, fitted.mask,
                         np.array([clicked[n] for n in result.landmarks_used])
                         if result.landmarks_used else None, projected)

    front = renderer.init_state(frontal_params(mean._replace(
        environment_map=best.environment_map, color_transform=best.color_transform,
        specular_exponent=best.specular_exponent), model))
    parts = [("diffuse", post.diffuse)] + ([("specular", post.specular)]
                                           if post.specular is not None else [])
    for name, part in parts:
        vmax = uncertainty_scale(part)
        for view, st in (("fitted", state), ("frontal", front)):
            rgb, mask = vertex_image(st, part.mean)
            write_png(out / f"albedo_{name}_{view}.png", encode_display(rgb), alpha=mask)
            save_uncertainty_map(out / f"uncertainty_{name}_{view}.png", st, part, name=name,
                                 view=view, vmax=vmax)
    save_traces(out / "traces.png", result)

    m = mean.momo
    verts = model.shape_instance(np.asarray(m.shape), np.asarray(m.expression)
                                 if model.expression is not None else None)
    write_mesh(out / "mesh.ply", verts, model.triangles, post.diffuse.mean.astype(np.float64),
               gamma=2.2)
    result.save_chain(out / "chain.h5")
    write_posterior_nc(out / "posterior.nc", fit_inference_data(
        result, loaded, {"image": target, "landmarks": clicked}, space))
    (out / "config.json").write_text(cfg.to_json() + "\n", encoding="utf-8")

    truth_error = None
    if truth is not None:
        truth_error = albedo_error(post, truth)
        if truth.params is not None:
            truth_error["pose_error_deg"] = _pose_error_deg(best, truth.params)
    albedo = {"colour_space": "linear sRGB", "display_encoding": "pure power 1/2.2",
              "interval": post.diffuse.level, "n_samples": post.n_samples,
              "n_vertices": int(visible.size), "n_visible": int(visible.sum()),
              "diffuse_std_visible_mean": float(post.diffuse.std[visible].mean())
              if visible.any() else None,
              "specular": post.specular is not None, **albedo_interval_fields(post)}
    files = [p.name for p in out.iterdir()] + ["summary.json", "report.html"]
    summary = build_summary(result, model_sha256=loaded.sha256, model_uri=loaded.uri,
                            inputs={**(inputs or {}), "face_box": None if face_box is None
                                    else list(face_box)},
                            landmark_err=lm_err, albedo=albedo, files=files,
                            model=model_colour_record(space),
                            truth_error=truth_error,
                            extra_timings={"outputs_s": time.perf_counter() - t0})
    if occlusion is not None:
        summary["occlusion"] = occlusion_record(*occlusion, result.noise["outlier_probability"])
    (out / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n",
                                      encoding="utf-8")
    from mcmcfit.outputs.report import write_report

    write_report(out / "report.html", summary)
    return summary


def fit_inference_data(result: FitResult, loaded, observed: dict, space):
    """Build a fit's ``InferenceData`` with its provenance (``posterior.nc``).

    Parameters
    ----------
    result : FitResult
        A single or a joint fit's (without warm-up records the burn-in is the warm-up).
    loaded : mcmcfit.jobs.fit_job.LoadedModel
    observed : dict
        ``observed`` of :func:`mcmcfit.outputs.inference_data.inference_data`.
    space : albedo_model.io.colour_space.ColourSpace
        The model's colour space, recorded in the attrs: the derived
        ``albedo_mean`` of an sRGB-texture model is in its encoded space.
    """
    cfg = result.config
    has_warmup = any(getattr(c, "warmup", None) is not None for c in result.chains)
    attrs = {"seed": int(result.seed), "model_sha256": str(loaded.sha256),
             "model_uri": str(loaded.uri), "mcmcfit_version": software_versions()["mcmcfit"],
             "software": software_versions(),
             "noise_model": {**{k: getattr(cfg, k) for k in _NOISE_FIELDS if hasattr(cfg, k)},
                             **dict(getattr(result, "noise", None) or {})},
             "config": cfg.to_dict(), "model_colour": model_colour_record(space)}
    if space.is_srgb:
        attrs["albedo_mean_space"] = ("the model's encoded sRGB texture values (a convergence "
                                      "monitor); posterior.npz holds the decoded linear albedo")
    return inference_data(result.chains, result.layout, result.template, loaded.model,
                          observed=observed, attrs=attrs,
                          burn_fraction=0.0 if has_warmup else cfg.burn_fraction)


def _pose_error_deg(fit, true) -> dict:
    """Absolute yaw / pitch / roll differences in degrees."""
    return {k: float(np.degrees(abs(getattr(fit.pose, k) - getattr(true.pose, k))))
            for k in ("yaw", "pitch", "roll")}
