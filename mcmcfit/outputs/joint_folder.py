"""Write the outputs of a joint fit (several photographs of one face) into a folder.

Files (the caller makes the folder atomic):

==================================  ====================================================
``posterior.npz``                   the shared albedo as a single fit's (``diffuse_mean``,
                                    ``_std``, ``_lo``, ``_hi``, ...), ``visible``: vertices
                                    any photograph saw, ``visible_count`` (n,) how many,
                                    ``visible_images`` (k, n) which
``image<k>/target.png``, ``fit.png``  each photograph, and its best fit rendered over it
``image<k>/fit_landmarks.png``      its target and fitted landmarks
``image<k>/best.rps``, ``mean.rps``   its scene at the best sample and the posterior mean
``albedo_<part>_frontal.png``       the posterior-mean albedo, frontal, display-encoded
``uncertainty_<part>_frontal.png``  its posterior std, the vertices no photograph saw
                                    outlined in red
``seen_frontal.png``                the share of the photographs that saw each vertex
                                    (black: none did; their albedo is the prior's)
``traces.png``                      log densities and a few parameters per step, per chain
``samples.npz``                     every chain's kept draws (``samples`` (chains, draws, d),
                                    ``names``) and per-step log densities
``chain.h5``                        every chain, every stage (one template per photograph)
``posterior.nc``                    the image stage as an ArviZ ``InferenceData``: the
                                    shared ``shape`` and ``albedo``, every photograph's
                                    blocks with an ``image`` dimension, ``observed_data``
                                    ``image<k>`` and ``landmarks<k>``
``mesh.ply``                        the identity's mean shape (neutral expression) with the
                                    posterior-mean diffuse albedo (gamma 2.2)
``config.json``, ``summary.json``   the settings; the summary (as a single fit's, with
                                    ``images``: per photograph its inputs, visible vertices
                                    and landmark error)
``report.html``                     everything above on one page, a row per photograph
==================================  ====================================================

This module imports :mod:`albedo_model` (io, render.renderer), :mod:`mcmcfit.fitting.result`,
:mod:`mcmcfit.targets.landmarks` and the other :mod:`mcmcfit.outputs` modules
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
from albedo_model.render.renderer import Renderer
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
from mcmcfit.outputs.folder import fit_inference_data
from mcmcfit.outputs.inference_data import write_posterior_nc
from mcmcfit.outputs.posterior import visible_vertices
from mcmcfit.outputs.summary import build_summary, json_safe, landmark_errors
from mcmcfit.outputs.truth import Truth, albedo_error
from mcmcfit.outputs.vertex_maps import encode_display, frontal_params, vertex_image
from mcmcfit.targets.landmarks import target_landmarks

__all__ = ["write_joint_outputs"]


def _image_outputs(out: Path, k: int, renderer: Renderer, best, mean, image: np.ndarray,
                   landmarks, used: tuple[str, ...], srgb: bool) -> tuple[np.ndarray, dict | None]:
    """Write image ``k``'s pictures and scenes; return its visible vertices and landmark error."""
    folder = out / f"image{k}"
    folder.mkdir()
    state = renderer.init_state(best)
    rendered = renderer.image(state)
    shown = np.clip(rendered.image, 0.0, 1.0) if srgb else encode_display(rendered.image)
    target = np.clip(np.asarray(image, np.float64), 0.0, 1.0)
    write_png(folder / "target.png", target)
    write_png(folder / "fit.png", np.where(rendered.mask[..., None], shown, target))
    write_rps(folder / "best.rps", best)
    write_rps(folder / "mean.rps", mean)
    clicked = target_landmarks(landmarks) if landmarks is not None else {}
    names = [n for n in used if n in clicked]
    err, projected = None, None
    if names:
        got, px, _ = renderer.landmarks(state, names)
        err = landmark_errors(clicked, got, px)
        projected = np.asarray(px)
    save_landmark_figure(folder / "fit_landmarks.png", target, np.asarray(shown, np.float32),
                         rendered.mask, np.array([clicked[n] for n in names]) if names else None,
                         projected)
    return visible_vertices(renderer, renderer.init_state(mean)), err


def write_joint_outputs(folder: str | os.PathLike, result: FitResult, loaded,
                        images: list[np.ndarray], *, landmarks: list | None = None,
                        inputs: list[dict] | None = None, truth: Truth | None = None) -> dict:
    """Write a joint fit's outputs into ``folder`` and return the summary dict.

    Parameters
    ----------
    folder : path-like
        An existing (empty, temporary) folder.
    result : FitResult
        Of :func:`mcmcfit.fitting.joint_fit.fit_joint`.
    loaded : mcmcfit.jobs.fit_job.LoadedModel
    images : list of (H, W, 3) float
        The photographs as fitted.
    landmarks : list, optional
        Per photograph, its target landmarks.
    inputs : list of dict, optional
        Per photograph, recorded in ``summary["images"]``.
    truth : Truth, optional
        The true albedo (visible: the vertices any photograph truly saw).
    """
    t0 = time.perf_counter()
    out = Path(folder)
    model, cfg = loaded.model, result.config
    best = result.best.params
    mean = result.mean_params if result.mean_params is not None else best
    space = model_colour_space(model, cfg.model_colour)
    renderer = fit_renderer(model, cfg, threads=cfg.threads)
    seen, per_image = [], []
    for k, image in enumerate(images):
        vis, err = _image_outputs(out, k, renderer, best.images[k], mean.images[k], image,
                                  None if landmarks is None else landmarks[k],
                                  result.landmarks_used, space.is_srgb)
        seen.append(vis)
        per_image.append({**((inputs or [{}] * len(images))[k]),
                          "visible_vertices": int(vis.sum()),
                          "landmark_rmse_px": None if err is None else err["rmse_px"]})
    seen = np.array(seen)
    visible = seen.any(axis=0)
    post = posterior_albedo(result, model, visible, residual_scale=estimate_residual_scale(
        result, model, list(mean.images), images))
    write_posterior_npz(out / "posterior.npz", post)
    with np.load(out / "posterior.npz") as z:
        arrays = dict(z)
    np.savez_compressed(out / "posterior.npz", **arrays,
                        visible_count=seen.sum(axis=0).astype(np.uint8), visible_images=seen)

    front = renderer.init_state(frontal_params(mean.images[0], model))
    parts = [("diffuse", post.diffuse)] + ([("specular", post.specular)]
                                           if post.specular is not None else [])
    for name, part in parts:
        rgb, mask = vertex_image(front, part.mean)
        write_png(out / f"albedo_{name}_frontal.png", encode_display(rgb), alpha=mask)
        save_uncertainty_map(out / f"uncertainty_{name}_frontal.png", front, part, name=name,
                             view="frontal", vmax=uncertainty_scale(part), unseen=~visible)
    count, mask = vertex_image(front, seen.sum(axis=0).astype(np.float64))
    write_png(out / "seen_frontal.png", np.clip(count / max(len(images), 1), 0.0, 1.0),
              alpha=mask)
    save_traces(out / "traces.png", result,
                columns=("image0.pose.yaw", "image1.pose.yaw", "albedo.0", "shape.0"))
    recs = result.records(2)
    if recs:
        n = min(r.samples.shape[0] for r in recs)
        steps = min(r.steps for r in recs)
        np.savez_compressed(out / "samples.npz",
                            samples=np.stack([r.samples[:n] for r in recs]),
                            names=np.array(result.layout.names),
                            log_lik_img=np.stack([r.log_lik_img[:steps] for r in recs]),
                            log_prior=np.stack([r.log_prior[:steps] for r in recs]))
    shape = model.shape_instance(np.asarray(mean.images[0].momo.shape))  # neutral expression
    write_mesh(out / "mesh.ply", shape, model.triangles, post.diffuse.mean.astype(np.float64),
               gamma=2.2)
    result.save_chain(out / "chain.h5")
    clicked = [target_landmarks(lm) if lm is not None else {}
               for lm in (landmarks or [None] * len(images))]
    write_posterior_nc(out / "posterior.nc", fit_inference_data(
        result, loaded, {"images": [np.clip(np.asarray(im, np.float64), 0.0, 1.0)
                                    for im in images], "landmarks": clicked}, space))
    (out / "config.json").write_text(cfg.to_json() + "\n", encoding="utf-8")
    truth_error = albedo_error(post, truth) if truth is not None else None
    albedo = {"colour_space": "linear sRGB", "interval": post.diffuse.level,
              "n_samples": post.n_samples, "n_vertices": int(visible.size),
              "n_visible": int(visible.sum()),
              "n_visible_by_all": int(seen.all(axis=0).sum()),
              "diffuse_std_visible_mean": float(post.diffuse.std[visible].mean())
              if visible.any() else None,
              "specular": post.specular is not None, **albedo_interval_fields(post)}
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    summary = build_summary(result, model_sha256=loaded.sha256, model_uri=loaded.uri,
                            inputs={"images": len(images)}, landmark_err=None, albedo=albedo,
                            files=[*files, "summary.json", "report.html"],
                            model=model_colour_record(space),
                            truth_error=truth_error,
                            extra_timings={"outputs_s": time.perf_counter() - t0})
    summary["images"] = json_safe(per_image)
    (out / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n",
                                      encoding="utf-8")
    from mcmcfit.outputs.report import write_report

    write_report(out / "report.html", summary)
    return summary
