"""Build an albedo model from a capture folder (``mcmcfit pipeline build``).

Stages (Smith et al. 2020, Sec. 3-5):

1. per subject (cached, resumable): read the polarised images, cameras and
   registered mesh, and compute stitched diffuse and specular albedo
   (:mod:`pipeline.lightstage.processing`); external single-view scans are
   sampled, linearised and ISO-normalised (:mod:`pipeline.lightstage.external_scans`);
2. external scans are colour-matched to the captures (3x3 transform of the
   mean diffuse maps);
3. masked vertices (listed in a subject's ``mask.txt``, or not observed in this
   subject though most others observe them; see
   :func:`pipeline.lightstage.assembly.inpainting_masks`) are completed by
   statistical inpainting and Poisson blending, and eyeball specular is set to
   the 95th percentile of its estimates (:mod:`pipeline.texturing.inpainting`); regions
   few subjects observe keep the stitching's zero-gradient fill; final maps are
   clipped to [0, 1];
4. symmetry-augmented PCA in the paper's three variants
   (:mod:`pipeline.modelling.pca_variants`), a shape model from the registered
   meshes, and the leave-one-out specular generalisation of the variants
   (:mod:`pipeline.modelling.generalisation`).

Per-subject results live in a work folder as ``<id>.npz``, keyed by a hash of
the processing settings and the input files' names, sizes and modification
times: a rerun skips finished subjects, and a changed input is reprocessed.

This module imports :mod:`albedo_model` (``errors``, ``io.atomic``), :mod:`pipeline.lightstage`
modules and, when a subject is processed, :mod:`pipeline.texturing` (``cameras``,
``capture_io``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.atomic import atomic_path
from pipeline.lightstage.capture_folder import (
    LightstageSpec,
    SubjectEntry,
    TemplateInfo,
    list_subjects,
    read_lightstage,
    read_template,
)
from pipeline.lightstage.external_scans import ExternalEntry, ExternalScan, list_external
from pipeline.lightstage.processing import ProcessingOptions, SubjectAlbedo

__all__ = ["BuildReport", "BuildSettings", "build_model", "options_from_spec",
           "process_subject_entry"]

#: Bump when the processing changes what it computes (invalidates cached subjects).
PROCESSING_VERSION = 3


@dataclasses.dataclass(frozen=True)
class BuildSettings:
    """Options of :func:`build_model`.

    Attributes
    ----------
    rank : int, optional
        Components kept in the albedo and shape models (default: all).
    jobs : int
        Worker processes for the per-subject stage.
    inpaint_iterations : int
        Statistical inpainting rounds (the second uses a model of completed maps).
    loo_components : int, optional
        Largest number of modes in the leave-one-out curves (default: all).
    variants : bool
        Also write the ``independent`` and ``concatenated`` models.
    """

    rank: int | None = None
    jobs: int = 1
    inpaint_iterations: int = 2
    loo_components: int | None = None
    variants: bool = True


class BuildReport(NamedTuple):
    """What :func:`build_model` did (also written as ``<output stem>_build.json``).

    Attributes
    ----------
    files : dict of str -> str
        Written files by role.
    subjects, external : list of str
    reused : int
        Subjects and scans taken from the work folder.
    seconds : dict of str -> float
    accuracy : dict
        Per-subject and overall RMSE against ``truth.npz`` (synthetic data only).
    generalisation : dict
        Mean leave-one-out specular error per variant and number of modes.
    """

    files: dict
    subjects: list
    external: list
    reused: int
    seconds: dict
    accuracy: dict
    generalisation: dict


def options_from_spec(spec: LightstageSpec) -> ProcessingOptions:
    """Return the processing options of a parsed ``lightstage.json``."""
    return ProcessingOptions(
        colour=spec.colour(), leds_camera=spec.leds_mm, led_intensity=spec.led_intensity,
        centre_camera=spec.centre_mm, exposure=spec.exposure, iso_reference=spec.iso_reference,
        polariser_transmission=spec.polariser_transmission, shading=spec.shading,
        shadows=spec.shadows, specular_exponent=spec.specular_exponent)


def _cache_key(spec: LightstageSpec, files: list[Path]) -> str:
    h = hashlib.sha256(json.dumps([PROCESSING_VERSION, spec.to_json()], sort_keys=True).encode())
    for f in files:
        if not f.is_file():
            raise InputError(f"{f}: file not found")
        st = f.stat()
        h.update(f"{f.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    return h.hexdigest()


def _load_registered(path: Path, template: TemplateInfo) -> np.ndarray:
    from pipeline.texturing.capture_io import load_mesh

    v, _ = load_mesh(path)
    if len(v) != len(template.vertices):
        raise FormatError(path, f"has {len(v)} vertices, the template {len(template.vertices)}")
    return v


def process_subject_entry(entry: SubjectEntry, template: TemplateInfo,
                          options: ProcessingOptions) -> tuple[SubjectAlbedo, np.ndarray]:
    """Stitched albedo of one subject folder, and its registered vertices (n, 3)."""
    from pipeline.lightstage.processing import process_subject
    from pipeline.texturing.cameras import load_cameras
    from pipeline.texturing.capture_io import load_view_images

    rig = load_cameras(entry.cameras)
    if len(rig.cameras) != len(entry.view_names):
        raise FormatError(entry.cameras, f"has {len(rig.cameras)} views but subject.json "
                                         f"lists {len(entry.view_names)}")
    verts = _load_registered(entry.registered, template)
    images = load_view_images([*entry.parallel, *entry.perpendicular])
    k = len(entry.view_names)
    albedo = process_subject(verts, template.triangles, rig.cameras, images[:k], images[k:],
                             iso=entry.iso, options=options, stitching=rig.settings)
    return albedo, verts


def _process_external(entry: ExternalEntry, template: TemplateInfo,
                      spec: LightstageSpec) -> tuple[ExternalScan, np.ndarray]:
    from pipeline.lightstage.external_scans import sample_external_scan
    from pipeline.texturing.cameras import load_cameras
    from pipeline.texturing.capture_io import load_view_images

    rig = load_cameras(entry.cameras)
    verts = _load_registered(entry.registered, template)
    diff, spec_map = load_view_images([entry.diffuse, entry.specular])
    scan = sample_external_scan(diff, spec_map, rig.cameras[0], verts, template.triangles,
                                iso=entry.iso, iso_reference=spec.iso_reference,
                                gamma=entry.gamma,
                                boundary_distance_px=rig.settings.boundary_distance_px)
    return scan, verts


@lru_cache(maxsize=2)
def _state(captures: str) -> tuple[LightstageSpec, TemplateInfo, ProcessingOptions]:
    spec = read_lightstage(captures)
    return spec, read_template(captures), options_from_spec(spec)


def _save(path: Path, key: str, arrays: dict) -> None:
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, key=np.array(key), **arrays)


def _cached(path: Path, key: str) -> dict | None:
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) != key:
                return None
            return {k: np.asarray(z[k]) for k in z.files if k != "key"}
    except (OSError, ValueError, KeyError):
        return None


def _work_item(args: tuple[str, str, str, str, str]) -> str:
    """Process one subject or scan into its cache file (runs in worker processes)."""
    captures, kind, folder, cache, key = args
    spec, template, options = _state(captures)
    if kind == "subjects":
        entry = next(e for e in list_subjects(captures) if str(e.folder) == folder)
        albedo, verts = process_subject_entry(entry, template, options)
        arrays = {"diffuse": albedo.diffuse, "specular": albedo.specular,
                  "diffuse_observed": albedo.diffuse_observed,
                  "specular_observed": albedo.specular_observed, "vertices": verts}
    else:
        entry = next(e for e in list_external(captures) if str(e.folder) == folder)
        scan, verts = _process_external(entry, template, spec)
        arrays = {"diffuse": scan.diffuse, "specular": scan.specular,
                  "diffuse_observed": scan.observed, "specular_observed": scan.observed,
                  "vertices": verts}
    _save(Path(cache), key, arrays)
    return Path(folder).name


def build_model(captures: str | os.PathLike, output: str | os.PathLike, *,
                work_dir: str | os.PathLike | None = None,
                settings: BuildSettings | None = None,
                progress: Callable[[str, int, int], None] | None = None) -> BuildReport:
    """Process a capture folder and write the albedo models (see the module notes).

    Parameters
    ----------
    captures : path-like
        Capture folder (:mod:`pipeline.lightstage.capture_folder`).
    output : path-like
        The model file (``.h5``, AlbedoMM layout, ``transferred`` variant). Beside
        it: ``<stem>_independent.h5``, ``<stem>_concatenated.h5``,
        ``<stem>_specgen.png`` (leave-one-out plot) and ``<stem>_build.json``.
    work_dir : path-like, optional
        Per-subject results (default ``<output>.work``).
    settings : BuildSettings, optional
    progress : callable, optional
        ``progress(name, done, total)`` after each subject or scan.

    Returns
    -------
    BuildReport
    """
    from pipeline.lightstage.assembly import assemble_models

    settings = BuildSettings() if settings is None else settings
    t0 = time.perf_counter()
    root = Path(captures).resolve()
    out = Path(output)
    if not out.parent.is_dir():
        raise InputError(f"{out.parent}: output folder does not exist")
    spec, template, _ = _state(str(root))
    subjects = list_subjects(root)
    external = list_external(root)
    if len(subjects) < 2:
        raise InputError(f"{root}: needs at least 2 subjects under subjects/, found "
                         f"{len(subjects)}")
    work = Path(work_dir) if work_dir is not None else out.with_name(out.name + ".work")
    work.mkdir(parents=True, exist_ok=True)
    items = []
    for kind, entries in (("subjects", subjects), ("external", external)):
        (work / kind).mkdir(exist_ok=True)
        for e in entries:
            name = e.folder.name
            items.append((kind, e, work / kind / f"{name}.npz",
                          _cache_key(spec, e.input_files())))
    todo = [(str(root), kind, str(e.folder), str(c), k) for kind, e, c, k in items
            if _cached(c, k) is None]
    reused = len(items) - len(todo)
    done = reused
    say = progress or (lambda name, i, n: None)
    if todo:
        if settings.jobs <= 1 or len(todo) == 1:
            for args in todo:
                done += 1
                say(_work_item(args), done, len(items))
        else:
            import multiprocessing

            ctx = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(max_workers=settings.jobs, mp_context=ctx) as pool:
                for name in pool.map(_work_item, todo):
                    done += 1
                    say(name, done, len(items))
    t1 = time.perf_counter()
    results = {}
    for kind, e, c, k in items:
        data = _cached(c, k)
        if data is None:
            raise InputError(f"{c}: processed result missing or stale")
        results[(kind, e.folder.name)] = (e, data)
    files, accuracy, generalisation, seconds = assemble_models(
        results, template, spec, out, settings=settings, captures=root)
    seconds = {"per-subject processing": t1 - t0, **seconds,
               "total": time.perf_counter() - t0}
    report = BuildReport(files, [e.folder.name for e in subjects],
                         [e.folder.name for e in external], reused, seconds, accuracy,
                         generalisation)
    report_path = out.with_name(out.stem + "_build.json")
    files["report"] = str(report_path)
    with atomic_path(report_path) as tmp:
        tmp.write_text(json.dumps(report._asdict(), indent=1, default=float) + "\n")
    return report

