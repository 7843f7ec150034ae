"""Stitch a lightstage capture end to end: files in, per-vertex texture out.

mesh + photographs + camera file -> per-view samples
(:mod:`pipeline.texturing.view_sampling`) -> screened-Poisson stitch
(:mod:`pipeline.texturing.poisson_stitching`) -> ``texture.npz``, with the time of each stage.

The texture file (NumPy ``.npz``, no pickled objects) holds

==================  ==============  =================================================
``colour``          (n, 3) float64  stitched colour, the photographs' [0, 1] scale
``samples``         (k, n, 3) f32   per-view bilinear samples
``weights``         (k, n) float32  per-view weights (cosine; 0 where invalid)
``valid``           (k, n) bool     per-view validity
``selected_view``   (m,) int16      view per triangle, -1 where none is valid
``screened``        (n,) bool       vertices screened to the reference view
``vertices``        (n, 3) float64  mesh frame
``triangles``       (m, 3) int32    0-based
``views``           (k,) str        photograph file names
==================  ==============  =================================================

and the scalars ``reference_view`` (0-based), ``lam``, ``boundary_distance_px``,
``no_view_weight`` and ``residual``. ``colour`` is the unclipped solution:
gradient-domain blending can overshoot [0, 1] by a few per cent at a few vertices.

This module imports :mod:`albedo_model` and :mod:`pipeline.texturing` modules (``cameras``,
``capture_io``, ``poisson_stitching``, ``view_sampling``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.atomic import atomic_path
from albedo_model.render.raycast import RayCaster
from pipeline.texturing.cameras import LightstageCamera, StitchSettings, load_cameras
from pipeline.texturing.capture_io import load_mesh, load_view_images
from pipeline.texturing.poisson_stitching import StitchResult, stitch
from pipeline.texturing.view_sampling import ViewSamples, sample_views

__all__ = ["StitchRun", "stitch_capture", "write_texture"]


class StitchRun(NamedTuple):
    """Everything a stitch produced.

    Attributes
    ----------
    vertices : (n, 3) float64
    triangles : (m, 3) int32
    views : tuple of str
        Photograph paths.
    images : list of (H, W, 3) arrays
        The decoded photographs (for previews).
    cameras : tuple of LightstageCamera
    samples : list of ViewSamples
    result : StitchResult
    settings : StitchSettings
        The settings used (camera file values, overridden by arguments).
    timings : dict of str -> float
        Seconds per stage: "load mesh", "load images", "ray caster", "sampling",
        "silhouette", "visibility", "solve", "total".
    no_view_weight : float
        Row weight of triangles without a view
        (:func:`pipeline.texturing.poisson_stitching.stitch`).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    views: tuple[str, ...]
    images: list
    cameras: tuple[LightstageCamera, ...]
    samples: list[ViewSamples]
    result: StitchResult
    settings: StitchSettings
    timings: dict
    no_view_weight: float = 0.01


def stitch_capture(mesh: str | os.PathLike, views: Sequence[str | os.PathLike],
                   cameras: str | os.PathLike, *, lam: float | None = None,
                   boundary_distance_px: float | None = None, reference_view: int | None = None,
                   reference_region: str = "valid", no_view_weight: float = 0.01,
                   mask_scale: int = 4, threads: int = 2) -> StitchRun:
    """Sample the photographs onto the mesh and stitch them.

    Parameters
    ----------
    mesh : path-like
        Registered mesh (:func:`pipeline.texturing.capture_io.load_mesh`), in the cameras' world frame.
    views : sequence of path-like
        One photograph per view of the camera file, in the file's order.
    cameras : path-like
        Camera file (:mod:`pipeline.texturing.cameras`).
    lam, boundary_distance_px, reference_view : optional
        Override the camera file's stitching settings.
    reference_region, no_view_weight, mask_scale :
        See :func:`pipeline.texturing.poisson_stitching.stitch` and
        :func:`pipeline.texturing.view_sampling.sample_view`.
    threads : int
        Threads for decoding the photographs.

    Returns
    -------
    StitchRun
    """
    timings: dict[str, float] = {}
    start = t = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal t
        now = time.perf_counter()
        timings[name] = timings.get(name, 0.0) + now - t
        t = now

    rig = load_cameras(cameras)
    view_paths = tuple(str(v) for v in views)
    if len(view_paths) != len(rig.cameras):
        raise InputError(f"{cameras}: describes {len(rig.cameras)} views but "
                         f"{len(view_paths)} photographs were given")
    settings = rig.settings
    if lam is not None:
        settings = replace(settings, lam=float(lam))
    if boundary_distance_px is not None:
        settings = replace(settings, boundary_distance_px=float(boundary_distance_px))
    if reference_view is not None:
        settings = replace(settings, reference_view=int(reference_view))
    if not 0 <= settings.reference_view < len(view_paths):
        raise InputError(f"reference view {settings.reference_view} is not one of the "
                         f"{len(view_paths)} views (0-based)")
    vertices, triangles = load_mesh(mesh)
    lap("load mesh")
    images = load_view_images(view_paths, threads=threads)
    for path, image, camera in zip(view_paths, images, rig.cameras):
        if image.shape[:2] != tuple(camera.image_size):
            raise FormatError(path, f"is {image.shape[1]}x{image.shape[0]} pixels but its camera "
                                    f"expects {camera.image_size[1]}x{camera.image_size[0]}")
    lap("load images")
    caster = RayCaster(vertices, triangles)
    lap("ray caster")
    samples = sample_views(images, rig.cameras, vertices, triangles, caster=caster,
                           boundary_distance_px=settings.boundary_distance_px,
                           mask_scale=mask_scale, timings=timings)
    t = time.perf_counter()
    result = stitch(vertices, triangles, np.stack([s.colour for s in samples]),
                    np.stack([s.weight for s in samples]), lam=settings.lam,
                    reference_view=settings.reference_view, reference_region=reference_region,
                    no_view_weight=no_view_weight)
    lap("solve")
    timings["total"] = time.perf_counter() - start
    return StitchRun(vertices, triangles, view_paths, images, rig.cameras, samples, result,
                     settings, timings, float(no_view_weight))


def write_texture(path: str | os.PathLike, run: StitchRun) -> None:
    """Write the texture file described in the module notes (atomically)."""
    arrays = {
        "colour": run.result.colour.astype(np.float64),
        "samples": np.stack([s.colour for s in run.samples]).astype(np.float32),
        "weights": np.stack([s.weight for s in run.samples]).astype(np.float32),
        "valid": np.stack([s.valid for s in run.samples]),
        "selected_view": run.result.selected_view.astype(np.int16),
        "screened": run.result.screened,
        "vertices": run.vertices, "triangles": run.triangles.astype(np.int32),
        "views": np.array([Path(v).name for v in run.views], dtype=str),
        "reference_view": np.int64(run.settings.reference_view),
        "lam": np.float64(run.settings.lam),
        "boundary_distance_px": np.float64(run.settings.boundary_distance_px),
        "no_view_weight": np.float64(run.no_view_weight),
        "residual": np.float64(run.result.residual),
    }
    with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
