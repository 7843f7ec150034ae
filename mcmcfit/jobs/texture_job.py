"""Textures of a fit: its per-vertex posterior albedo and uncertainty baked into images.

A fit's result folder holds per-vertex maps (``posterior.npz``); this job bakes
them into square textures through the model's UV atlas
(:func:`albedo_model.texture.bake.bake_vertex_values`) and exports the
posterior-mean mesh with the textures on (:mod:`albedo_model.io.textured_mesh`).

The UV atlas is the model file's (the built-in models carry one). A model
file without one gets an atlas computed once from its reference mesh with
xatlas and cached under ``<cache>/uv-atlas/<model sha256>.npz``
(:func:`albedo_model.default_model.cache_dir`).

Files written into the texture folder (default ``<fit>/texture``, atomically):

=================================  ===================================================
``<map>_linear16.png``             16-bit linear values (the numbers of posterior.npz)
``<map>_srgb8.png``                8-bit, sRGB-encoded (for viewers, Blender, glTF)
``visible.png``                    8-bit mask: vertices the photograph saw
``mesh.obj``, ``mesh.mtl``         posterior-mean shape, diffuse mean as ``map_Kd``
                                   (specular mean as ``map_Ks``)
``mesh.glb``                       the same as binary glTF, diffuse texture embedded
``texture.json``                   size, maps, model hash, atlas source, round-trip check
=================================  ===================================================

Maps: ``{diffuse,specular}_{mean,std,coef_std}`` (std: predictive when the model
has a residual variance, else coefficient-only; see ``posterior.npz``).

This module imports :mod:`albedo_model` (``default_model``, ``errors``, ``uv_atlas``,
``io``, ``texture``) and :mod:`mcmcfit.jobs` (``fit_job``, ``model_spec``).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.uv_atlas import UVAtlas

__all__ = ["TEXTURE_MAPS", "model_uv_atlas", "write_fit_textures"]

#: Per-vertex fields of ``posterior.npz`` baked, per albedo part.
TEXTURE_MAPS = ("mean", "std", "coef_std")


def model_uv_atlas(model: MorphableModel, sha256: str) -> tuple[UVAtlas, str]:
    """Return the model's UV atlas and where it came from (its file, the cache, or xatlas now).

    Parameters
    ----------
    model : MorphableModel
    sha256 : str
        Hex SHA-256 of the model file (names the cached atlas).

    Returns
    -------
    (UVAtlas, str)
    """
    from albedo_model.default_model import cache_dir
    from albedo_model.io.atomic import atomic_path
    from albedo_model.uv_atlas import compute_uv_atlas

    if model.uv_atlas is not None:
        return model.uv_atlas, "model file"
    path = cache_dir() / "uv-atlas" / f"{sha256}.npz"
    if path.is_file():
        with np.load(path) as z:
            atlas = UVAtlas(z["uv"], z["uv_triangles"])
        atlas.check_mesh(model.triangles, model.n_vertices)
        return atlas, f"cached: {path}"
    print(f"computing a UV atlas for this model with xatlas (once; {model.n_triangles} "
          "triangles)...", file=sys.stderr)
    atlas = compute_uv_atlas(model.vertices, model.triangles)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, uv=atlas.uv, uv_triangles=atlas.uv_triangles)
    return atlas, f"computed with xatlas, cached: {path}"


def _read_fit(fit_dir: Path) -> tuple[dict, dict, object]:
    from albedo_model.io.rps import read_rps

    for name in ("summary.json", "posterior.npz", "mean.rps"):
        if not (fit_dir / name).is_file():
            raise InputError(f"{fit_dir}: not a fit's result folder (no {name})")
    summary = json.loads((fit_dir / "summary.json").read_text(encoding="utf-8"))
    with np.load(fit_dir / "posterior.npz") as z:
        post = {k: z[k] for k in z.files}
    return summary, post, read_rps(fit_dir / "mean.rps")


def write_fit_textures(fit_dir: str | os.PathLike, out_dir: str | os.PathLike | None = None, *,
                       size: int = 1024, model: str | None = None,
                       force: bool = False) -> dict:
    """Bake a fit's posterior albedo maps into textures and export the textured mesh.

    Parameters
    ----------
    fit_dir : path-like
        A fit's result folder (``mcmcfit fit`` / ``demo`` / ``batch``).
    out_dir : path-like, optional
        Texture folder (default ``<fit_dir>/texture``); replaced only with ``force``.
    size : int
        Texels a side (at least 16).
    model : str, optional
        Model file or built-in name (default: the fit's ``model_uri``). A file
        whose SHA-256 differs from the fit's is accepted when its mesh matches
        the fit's arrays (a warning says so).
    force : bool
        Replace an existing texture folder.

    Returns
    -------
    dict
        The ``texture.json`` record.
    """
    from albedo_model.io.colour_space import encode_texture
    from albedo_model.io.image_io import write_png
    from albedo_model.io.model_files import file_sha256
    from albedo_model.io.textured_mesh import write_textured_mesh
    from albedo_model.texture.bake import bake_vertex_values, sample_texture
    from albedo_model.uv_atlas import uv_vertices
    from mcmcfit.jobs.fit_job import atomic_folder
    from mcmcfit.jobs.model_spec import load_model_spec, resolve_model

    start = time.perf_counter()
    fit = Path(fit_dir)
    summary, post, mean = _read_fit(fit)
    spec = model or summary.get("model_uri") or "default"
    path = resolve_model(spec)
    loaded = load_model_spec(str(path))
    sha = file_sha256(path)
    n = len(post["diffuse_mean"])
    if loaded.n_vertices != n:
        raise InputError(f"{path}: the model has {loaded.n_vertices} vertices, the fit's maps "
                         f"{n}: not the model of this fit (pass the right one with --model)")
    if sha != summary.get("model_sha256"):
        print(f"warning: {path} is not the file the fit used (SHA-256 differs); its mesh matches "
              "the fit's maps, so they are baked on it", file=sys.stderr)
    atlas, atlas_source = model_uv_atlas(loaded, sha)
    parts = [p for p in ("diffuse", "specular") if f"{p}_mean" in post]
    maps = {f"{p}_{m}": post[f"{p}_{m}"] for p in parts for m in TEXTURE_MAPS}
    values = np.concatenate([np.asarray(a, np.float64) for a in maps.values()]
                            + [np.asarray(post["visible"], np.float64)[:, None]], axis=1)
    baked = bake_vertex_values(atlas, loaded.triangles, values, int(size))
    if baked.collisions:
        print(f"warning: {baked.collisions} texels hold two vertices of different value at size "
              f"{size}; a larger --size keeps every vertex", file=sys.stderr)
    owner = uv_vertices(baked.atlas, loaded.triangles)
    round_trip = float(np.abs(sample_texture(baked.image, baked.atlas.uv)
                              - values[np.maximum(owner, 0)]).max())
    verts = loaded.shape_instance(np.asarray(mean.momo.shape), np.asarray(mean.momo.expression)
                                  if loaded.expression is not None else None)
    out = Path(out_dir) if out_dir is not None else fit / "texture"
    files: dict[str, str] = {}
    with atomic_folder(out, force=force) as tmp:
        for i, name in enumerate(maps):
            linear = baked.image[..., 3 * i:3 * i + 3]
            write_png(tmp / f"{name}_linear16.png", linear, bits=16)
            write_png(tmp / f"{name}_srgb8.png", encode_texture(np.clip(linear, 0.0, 1.0)))
            files[name] = f"{name}_linear16.png, {name}_srgb8.png"
        write_png(tmp / "visible.png", (baked.image[..., -1] >= 0.5).astype(np.float64))
        diffuse8 = np.round(np.clip(encode_texture(np.clip(baked.image[..., 0:3], 0.0, 1.0)),
                                    0.0, 1.0) * 255).astype(np.uint8)
        written = write_textured_mesh(tmp, "mesh", verts, loaded.triangles, baked.atlas,
                                      "diffuse_mean_srgb8.png", diffuse8,
                                      "specular_mean_srgb8.png" if "specular" in parts else None)
        record = {
            "size": int(size), "maps": files, "visible": "visible.png",
            "mesh": [p.name for p in written], "model_uri": str(spec), "model_sha256": sha,
            "fit_model_sha256": summary.get("model_sha256"), "uv_atlas": atlas_source,
            "texture_points": baked.atlas.n_points, "collisions": baked.collisions,
            "round_trip_max_abs_error": round_trip,
            "covered_fraction": float(baked.covered.mean()),
            "seconds": round(time.perf_counter() - start, 2),
        }
        (tmp / "texture.json").write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    return record
