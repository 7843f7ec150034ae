"""Integrating external single-view scans (Smith et al. 2020, "Integrating 3DRFE").

3DRFE-like scans provide, per subject, diffuse and specular albedo *maps*
photographed from the one polarisation-calibrated view, a mesh and the
camera of those maps. Their processing:

1. sampling: the registered template is projected into the maps with the
   scan's camera (:mod:`pipeline.texturing.view_sampling`: visibility, cosine weights,
   silhouette margin); observed vertices keep their samples and the others
   are filled with zero gradient (:func:`pipeline.texturing.poisson_stitching.stitch` with the
   one view);
2. linearisation: the maps are stored in a non-linear space; the inverse of a
   pure gamma 2.2 brings them back to linear values;
3. ISO normalisation: the camera gain was set per subject, so each map is
   divided by its ISO number (relative to ``iso_reference``);
4. colour: the maps differ from ours by an unknown scale and colour
   transform; the 3x3 matrix ``M`` that maps the mean diffuse map of the
   external scans onto the mean of our scans in the least-squares sense
   (over vertices observed in both sets) is applied to every external
   diffuse and specular map. Skin colours span little of the colour space,
   so ``M`` is well determined only along them, which is where it is used.

Folder layout: ``CAPTURES/external/<id>/scan.json`` (see
:mod:`pipeline.lightstage.capture_folder`), its maps, ``cameras.json`` (one view) and the
registered mesh.

This module imports :mod:`albedo_model.errors` and :mod:`pipeline.texturing` (``cameras``,
``json_files``, ``poisson_stitching``, ``view_sampling``).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import NamedTuple

import numpy as np

from albedo_model.errors import FormatError, InputError
from pipeline.texturing.cameras import LightstageCamera
from pipeline.texturing.json_files import read_json_object
from pipeline.texturing.poisson_stitching import stitch
from pipeline.texturing.view_sampling import bilinear_sample, sample_view

__all__ = [
    "ExternalEntry", "ExternalScan", "apply_colour_transform", "fit_colour_transform",
    "integrate_external", "linearise", "list_external", "sample_external_scan",
]


_MIN_FIT_VERTICES = 100


class ExternalScan(NamedTuple):
    """One external scan on the template (linear, ISO-normalised, before colour matching).

    Attributes
    ----------
    diffuse, specular : (n, 3) float64
    observed : (n,) bool
        Vertices with a valid sample (the rest is zero-gradient fill).
    """

    diffuse: np.ndarray
    specular: np.ndarray
    observed: np.ndarray


def linearise(image: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    """Inverse of a pure power encoding: ``x ** gamma`` of values clipped to [0, 1], float64."""
    if not gamma > 0:
        raise InputError(f"gamma must be positive, got {gamma}")
    return np.clip(np.asarray(image, np.float64), 0.0, 1.0) ** float(gamma)


def _unit(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    scale = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(img.dtype, 1.0)
    return img.astype(np.float64) / scale


def sample_external_scan(diffuse_map: np.ndarray, specular_map: np.ndarray,
                         camera: LightstageCamera, vertices: np.ndarray,
                         triangles: np.ndarray, *, iso: float, iso_reference: float = 100.0,
                         gamma: float = 2.2,
                         boundary_distance_px: float = 100.0) -> ExternalScan:
    """Run steps 1-3 of the module notes for one scan.

    Parameters
    ----------
    diffuse_map, specular_map : (H, W, 3) uint8, uint16 or float arrays
        Gamma-encoded albedo maps seen by ``camera``.
    camera : LightstageCamera
        World = the registered mesh frame.
    vertices : (n, 3) float array
        The template registered to the scan.
    triangles : (m, 3) int array
    iso : float
    iso_reference : float
    gamma : float
    boundary_distance_px : float

    Returns
    -------
    ExternalScan
    """
    if not iso > 0 or not iso_reference > 0:
        raise InputError("ISO values must be positive")
    gain = iso / iso_reference
    diff = linearise(_unit(diffuse_map), gamma) / gain
    spec = linearise(_unit(specular_map), gamma) / gain
    samples = sample_view(diff, camera, vertices, triangles,
                          boundary_distance_px=boundary_distance_px)
    spec_v, _ = bilinear_sample(spec, camera.project(np.asarray(vertices, float)))
    colours = np.concatenate([samples.colour, spec_v], axis=1)[None].astype(np.float64)
    if not samples.valid.any():
        raise InputError("no vertex of the registered mesh is visible in the scan's maps")
    res = stitch(vertices, triangles, colours, samples.weight[None].astype(np.float64),
                 lam=0.1, reference_view=0)
    # sampled values where observed; the zero-gradient solution only fills the rest
    out = np.where(samples.valid[:, None], colours[0], res.colour)
    return ExternalScan(out[:, :3], out[:, 3:], samples.valid.copy())


def _observed_mean(maps: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-vertex mean over the samples observing it, and the fraction of samples that do."""
    w = np.asarray(observed, np.float64)
    count = w.sum(axis=0)
    mean = (np.asarray(maps, np.float64) * w[..., None]).sum(axis=0) / np.maximum(count, 1)[:, None]
    return mean, count / len(w)


def fit_colour_transform(source: np.ndarray, target: np.ndarray, *,
                         ridge: float = 3e-3) -> np.ndarray:
    """Least-squares ``M`` (3, 3) with ``target ~ source @ M.T`` (rows are colours).

    Parameters
    ----------
    source, target : (k, 3) float arrays
    ridge : float
        Tikhonov weight, relative to the mean squared source colour, pulling
        ``M`` towards the per-channel scaling that fits the data. Skin colours
        lie close to a plane of the colour space, so the plain fit is
        undetermined across it; there (e.g. for grey specular albedo) the ridge
        keeps the transform a channel scaling instead of an arbitrary one.
        0: plain least squares.

    Returns
    -------
    (3, 3) float64
    """
    a = np.asarray(source, np.float64)
    b = np.asarray(target, np.float64)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 3 or len(a) < 3:
        raise InputError(f"need two (k >= 3, 3) colour arrays, got {a.shape} and {b.shape}")
    if ridge <= 0:
        m, *_ = np.linalg.lstsq(a, b, rcond=None)
        return m.T
    scale = (a * b).sum(axis=0) / np.maximum((a * a).sum(axis=0), 1e-300)
    mu = ridge * float(np.mean(a * a)) * len(a)
    # minimise |a M^T - b|^2 + mu |M - diag(scale)|^2, column by column of M^T
    lhs = a.T @ a + mu * np.eye(3)
    rhs = a.T @ b + mu * np.diag(scale)
    return np.linalg.solve(lhs, rhs).T


def apply_colour_transform(maps: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """Return ``maps @ matrix.T`` for (..., 3) colour maps."""
    return np.asarray(maps, np.float64) @ np.asarray(matrix, np.float64).T


def integrate_external(scans: list[ExternalScan], our_diffuse: np.ndarray,
                       our_observed: np.ndarray, *, fit_vertices: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step 4: colour-match the external scans to our own captures.

    Parameters
    ----------
    scans : list of ExternalScan
    our_diffuse : (S, n, 3) float array
        Our diffuse maps (linear sRGB).
    our_observed : (S, n) bool array
    fit_vertices : (n,) bool array, optional
        Restrict the fit to these vertices (e.g. skin: the eyeballs' sharp iris
        edges are sampled poorly and would pull the fit).

    Returns
    -------
    diffuse, specular : (E, n, 3) float64
        The external maps after the transform.
    matrix : (3, 3) float64
        ``M``, fitted on the mean diffuse maps over the vertices observed in
        every scan and every capture (so that both means average over the same
        people), or, when fewer than 100 such vertices exist, by at least half.
    """
    if not scans:
        raise InputError("no external scans to integrate")
    ext_d = np.stack([s.diffuse for s in scans])
    ext_s = np.stack([s.specular for s in scans])
    ext_mean, ext_ok = _observed_mean(ext_d, np.stack([s.observed for s in scans]))
    our_mean, our_ok = _observed_mean(our_diffuse, our_observed)
    allowed = np.ones(len(ext_mean), bool) if fit_vertices is None else np.asarray(
        fit_vertices, bool)
    # a mean over a subset of the people differs from the full mean by their skin tones:
    # fit where everybody is observed, unless that leaves too few vertices
    both = allowed & (ext_ok == 1.0) & (our_ok == 1.0)
    if both.sum() < _MIN_FIT_VERTICES:
        both = allowed & (ext_ok >= 0.5) & (our_ok >= 0.5)
    if both.sum() < 3:
        raise InputError("external scans and captures share fewer than 3 observed vertices")
    m = fit_colour_transform(ext_mean[both], our_mean[both])
    return apply_colour_transform(ext_d, m), apply_colour_transform(ext_s, m), m


@dataclasses.dataclass(frozen=True)
class ExternalEntry:
    """One ``external/<id>/scan.json``."""

    scan_id: str
    folder: Path
    iso: float
    gamma: float
    diffuse: Path
    specular: Path
    registered: Path
    cameras: Path

    def input_files(self) -> list[Path]:
        """Every file the processing reads."""
        return [self.folder / "scan.json", self.diffuse, self.specular, self.registered,
                self.cameras]


def _entry(folder: Path) -> ExternalEntry:
    path = folder / "scan.json"
    data = read_json_object(path)
    iso, gamma = data.get("iso", 100.0), data.get("gamma", 2.2)
    for key, value in (("iso", iso), ("gamma", gamma)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
            raise FormatError(path, f"'{key}' must be a positive number")
    names = {}
    for key, default in (("diffuse", "diffuse.png"), ("specular", "specular.png"),
                         ("registered", "registered.ply"), ("cameras", "cameras.json")):
        value = data.get(key, default)
        if not isinstance(value, str):
            raise FormatError(path, f"'{key}' must be a file name")
        names[key] = folder / value
    return ExternalEntry(folder.name, folder, float(iso), float(gamma), **names)


def list_external(folder: str | os.PathLike) -> list[ExternalEntry]:
    """List the scans under ``folder/external`` (sorted by name) that hold a ``scan.json``."""
    root = Path(folder) / "external"
    if not root.is_dir():
        return []
    return [_entry(d) for d in sorted(root.iterdir())
            if d.is_dir() and (d / "scan.json").is_file()]
