"""Population stage of ``pipeline build``: completion, modelling, evaluation, files.

Takes the per-subject results of :mod:`pipeline.lightstage.build` (stitched
maps and observed masks), integrates external scans, completes masked
vertices, builds the shape model and the three albedo model variants, runs
the leave-one-out comparison of the variants and writes everything. See
:mod:`pipeline.lightstage.build` for the stages.

This module imports :mod:`albedo_model`, :mod:`pipeline.lightstage` (``capture_folder``,
``external_scans``), :mod:`pipeline.modelling` and :mod:`pipeline.texturing.inpainting`.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from albedo_model.io.atomic import atomic_path
from albedo_model.model import MorphableModel
from albedo_model.pca import PCAPart, pca_from_data
from pipeline.modelling.pca_variants import build_albedo_parts
from pipeline.modelling.residual_variance import attach_residual_variance, loo_residual_variance
from pipeline.lightstage.capture_folder import LightstageSpec, TemplateInfo, read_vertex_mask
from pipeline.lightstage.external_scans import ExternalScan, integrate_external
from pipeline.texturing.inpainting import replace_eyeball_specular, statistical_inpaint
from pipeline.modelling.symmetry import mirror_flat

__all__ = ["assemble_models", "inpainting_masks", "shape_model_from_meshes"]


def shape_model_from_meshes(vertices: np.ndarray, symmetry: np.ndarray | None, *,
                            rank: int | None = None) -> PCAPart:
    """PCA of registered meshes (S, n, 3), mm; with ``symmetry`` each mesh is also mirrored."""
    flat = np.asarray(vertices, np.float64).reshape(len(vertices), -1)
    if symmetry is not None:
        flat = np.vstack([flat, np.stack([mirror_flat(f, symmetry) for f in flat])])
    return pca_from_data(flat, rank=rank)


def inpainting_masks(observed: np.ndarray, user: np.ndarray, *,
                     min_observed: float = 0.5) -> np.ndarray:
    """Which vertices of each sample statistical inpainting fills, (S, n) bool.

    The user's masks (artefacts), and the vertices a sample did not observe
    where at least ``min_observed`` of the samples did: there the others carry
    statistical information. Regions few samples observe keep the stitching's
    zero-gradient fill, which is smooth, whereas a statistical guess learnt from
    fills would only add structure that nobody measured.
    """
    obs = np.asarray(observed, bool)
    common = obs.mean(axis=0) >= min_observed
    return np.asarray(user, bool) | (~obs & common[None, :])


def _float32(part: PCAPart) -> PCAPart:
    residual = part.residual_variance
    return PCAPart(part.mean.astype(np.float32), part.basis.astype(np.float32),
                   part.variance.astype(np.float32), part.noise_variance,
                   None if residual is None else residual.astype(np.float32))


def _truth(entry) -> tuple[np.ndarray, np.ndarray] | None:
    path = getattr(entry, "truth", None) or (entry.folder / "truth.npz")
    if path is None or not Path(path).is_file():
        return None
    with np.load(path, allow_pickle=False) as z:
        return np.asarray(z["diffuse"]), np.asarray(z["specular"])


def _rmse(est: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    return float(np.sqrt(np.mean((est[mask] - truth[mask]) ** 2))) if mask.any() else float("nan")


def _accuracy(names, entries, kinds, stitched_d, stitched_s, final_d, final_s, obs_d,
              obs_s) -> dict:
    keys = ("diffuse", "specular", "diffuse_final", "specular_final")
    per = {}
    pooled = {kind: {k: [] for k in keys} for kind in ("subjects", "external")}
    for i, (name, entry, kind) in enumerate(zip(names, entries, kinds)):
        truth = _truth(entry)
        if truth is None:
            continue
        td, ts = truth
        per[name] = {
            "diffuse": _rmse(stitched_d[i], td, obs_d[i]),
            "specular": _rmse(stitched_s[i], ts, obs_s[i]),
            "diffuse_final": _rmse(final_d[i], td, obs_d[i]),
            "specular_final": _rmse(final_s[i], ts, obs_s[i]),
            "observed_diffuse": int(obs_d[i].sum()), "observed_specular": int(obs_s[i].sum()),
        }
        pool = pooled[kind]
        pool["diffuse"].append((stitched_d[i] - td)[obs_d[i]])
        pool["specular"].append((stitched_s[i] - ts)[obs_s[i]])
        pool["diffuse_final"].append((final_d[i] - td)[obs_d[i]])
        pool["specular_final"].append((final_s[i] - ts)[obs_s[i]])
    if not per:
        return {}
    out = {"per_subject": per,
           "note": "RMSE in linear sRGB over each subject's observed vertices; 'final' after "
                   "inpainting, eyeball specular and clipping; 'overall' pools the captured "
                   "subjects, 'external' the external scans"}
    for kind, label in (("subjects", "overall"), ("external", "external")):
        if pooled[kind]["diffuse"]:
            out[label] = {k: float(np.sqrt(np.mean(np.concatenate(v) ** 2)))
                          for k, v in pooled[kind].items()}
    return out


def assemble_models(results: dict, template: TemplateInfo, spec: LightstageSpec, out: Path, *,
                    settings, captures: Path) -> tuple[dict, dict, dict, dict]:
    """Stages 2-4 of :mod:`pipeline.lightstage.build` and the output files.

    Parameters
    ----------
    results : dict (kind, name) -> (entry, arrays)
        Cached per-subject arrays (``diffuse``, ``specular``, ``*_observed``, ``vertices``).
    template : TemplateInfo
    spec : LightstageSpec
    out : Path
        Main model file.
    settings : BuildSettings
    captures : Path

    Returns
    -------
    files, accuracy, generalisation, seconds : dicts
    """
    from albedo_model.io.momo_h5 import write_model_h5
    from pipeline.modelling.generalisation import plot_specular_generalisation, specular_generalisation

    t0 = time.perf_counter()
    n = len(template.vertices)
    own = [(name, e, d) for (kind, name), (e, d) in sorted(results.items()) if kind == "subjects"]
    ext = [(name, e, d) for (kind, name), (e, d) in sorted(results.items()) if kind == "external"]
    names = [x[0] for x in own]
    entries = [x[1] for x in own]
    kinds = ["subjects"] * len(own) + ["external"] * len(ext)
    diff = np.stack([d["diffuse"] for _, _, d in own])
    spec_maps = np.stack([d["specular"] for _, _, d in own])
    obs_d = np.stack([d["diffuse_observed"] for _, _, d in own]).astype(bool)
    obs_s = np.stack([d["specular_observed"] for _, _, d in own]).astype(bool)
    meshes = [d["vertices"] for _, _, d in own]
    user = np.stack([read_vertex_mask(e.mask, n) if e.mask is not None else np.zeros(n, bool)
                     for e in entries])
    colour_matrix = None
    if ext:
        scans = [ExternalScan(d["diffuse"], d["specular"], d["diffuse_observed"].astype(bool))
                 for _, _, d in ext]
        ext_d, ext_s, colour_matrix = integrate_external(scans, diff, obs_d & ~user,
                                                         fit_vertices=~template.eyeballs)
        diff = np.concatenate([diff, ext_d])
        spec_maps = np.concatenate([spec_maps, ext_s])
        ext_obs = np.stack([s.observed for s in scans])
        obs_d = np.concatenate([obs_d, ext_obs])
        obs_s = np.concatenate([obs_s, ext_obs])
        user = np.concatenate([user, np.zeros((len(ext), n), bool)])
        meshes += [d["vertices"] for _, _, d in ext]
        names += [x[0] for x in ext]
        entries += [x[1] for x in ext]
    obs_d &= ~user
    obs_s &= ~user
    t1 = time.perf_counter()
    mask_d, mask_s = inpainting_masks(obs_d, user), inpainting_masks(obs_s, user)
    final_d = statistical_inpaint(diff, mask_d, template.vertices, template.triangles,
                                  iterations=settings.inpaint_iterations)
    final_s = statistical_inpaint(spec_maps, mask_s, template.vertices, template.triangles,
                                  iterations=settings.inpaint_iterations)
    for i in range(len(final_s)):
        final_s[i] = replace_eyeball_specular(final_s[i], template.eyeballs, obs_s[i])
    final_d = np.clip(final_d, 0.0, 1.0)
    final_s = np.clip(final_s, 0.0, 1.0)
    t2 = time.perf_counter()
    accuracy = _accuracy(names, entries, kinds, diff, spec_maps, final_d, final_s, obs_d,
                         obs_s)

    sym = template.symmetry
    shape = _float32(shape_model_from_meshes(np.stack(meshes), sym, rank=settings.rank))
    mean_vertices = shape.mean.reshape(-1, 3)
    landmarks = {k: mean_vertices[i].astype(np.float64) for k, i in template.landmarks.items()}
    colour = spec.colour()
    provenance = {"builder": "pipeline.lightstage.build", "captures": str(captures),
                  "subjects": len(own), "external_scans": len(ext),
                  "symmetry_augmented": True, "camera_colour": colour.metadata()}
    if colour_matrix is not None:
        provenance["external_colour_transform"] = np.round(colour_matrix, 8).tolist()
    synthetic = any(_truth(e) is not None for e in entries)
    files = {}
    variants = ("transferred", "independent", "concatenated") if settings.variants \
        else ("transferred",)
    for variant in variants:
        parts = build_albedo_parts(final_d, final_s, sym, variant=variant, rank=settings.rank)
        parts = attach_residual_variance(parts, loo_residual_variance(
            final_d, final_s, sym, variant=variant, rank=settings.rank))
        metadata = {
            "description": "albedo model built by mcmcfit pipeline build from lightstage captures",
            "synthetic": "true" if synthetic else "false",
            "variant": variant, "colour_space": "linear sRGB",
            "gamma": "pure power 2.2 (AlbedoMM convention)",
            "provenance": json.dumps({**provenance, "variant": variant}, sort_keys=True),
            **colour.metadata(),
        }
        model = MorphableModel(mean_vertices, template.triangles, shape,
                               _float32(parts.diffuse), specular=_float32(parts.specular),
                               shared_albedo=parts.shared, landmarks=landmarks, symmetry=sym,
                               metadata=metadata)
        path = out if variant == "transferred" else out.with_name(f"{out.stem}_{variant}.h5")
        write_model_h5(model, path, layout="albedomm")
        files[variant] = str(path)
    t3 = time.perf_counter()
    loo = specular_generalisation(final_d, final_s, sym, max_components=settings.loo_components)
    plot = out.with_name(f"{out.stem}_specgen.png")
    plot_specular_generalisation(loo, plot)
    files["specgen"] = str(plot)
    k = loo["components"]
    generalisation = {
        "components": k.tolist(),
        "fit_mean": {v: e.tolist() for v, e in loo["fit_mean"].items()},
        "from_diffuse_mean": {v: e.tolist() for v, e in loo["from_diffuse_mean"].items()},
        "n_subjects": loo["n_subjects"],
    }
    seconds = {"completion": t2 - t1, "models": t3 - t2, "leave-one-out": time.perf_counter() - t3,
               "assembly": t1 - t0}
    maps = out.with_name(f"{out.stem}_maps.npz")
    with atomic_path(maps) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, names=np.array(names), diffuse=final_d.astype(np.float32),
                            specular=final_s.astype(np.float32),
                            stitched_diffuse=diff.astype(np.float32),
                            stitched_specular=spec_maps.astype(np.float32),
                            diffuse_observed=obs_d, specular_observed=obs_s)
    files["maps"] = str(maps)
    return files, accuracy, generalisation, seconds
