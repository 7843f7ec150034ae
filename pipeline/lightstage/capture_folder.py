"""The capture folder: what ``mcmcfit pipeline build`` reads (and ``simulate`` writes).

Layout (real lightstage data can be dropped in the same way)::

    CAPTURES/
      lightstage.json            the rig (below)
      template.npz               the registration template: vertices (n, 3) mm,
                                 triangles (m, 3), symmetry (n,), eyeballs (n,) bool,
                                 landmark_names (k,) str, landmark_indices (k,)
      camera.csv, led.csv        optional spectra named by lightstage.json
      subjects/<id>/
        subject.json             {"iso": 400, "views": [{"name": "frontal",
                                   "parallel": "frontal_parallel.tif",
                                   "perpendicular": "frontal_perpendicular.tif"}, ...],
                                  "registered": "registered.ply", "cameras": "cameras.json",
                                  "mask": "mask.txt" (optional), "truth": "truth.npz" (optional),
                                  "multiview": "multiview.json" (optional)}
        cameras.json             the photometric camera of each view, in the order of
                                 "views" (format: pipeline.texturing.cameras), world =
                                 the registered mesh's frame; its "stitching" block sets
                                 the silhouette margin, lambda and the reference view
        registered.ply           the template fitted to this subject (same vertex order)
        frontal_parallel.tif ... linear camera-raw RGB, 16-bit TIFF (e.g. dcraw -4 -T -o 0;
                                 16-bit PNGs are read as 8 bits by imageio: avoid them)
        mask.txt                 optional: 0-based vertex indices to inpaint, one per line
        multiview/, multiview.json   extra unpolarised views (not used by the build)
        truth.npz                synthetic data only: diffuse, specular (n, 3) linear sRGB
      external/<id>/             optional single-view scans (3DRFE-like)
        scan.json                {"iso": 200, "gamma": 2.2, "diffuse": "diffuse.png",
                                  "specular": "specular.png", "registered": "registered.ply",
                                  "cameras": "cameras.json"}

``lightstage.json``::

    {"format": "mcmcfit-lightstage", "version": 1,
     "camera": {"name": "Nikon 5100 (NPL)"} | {"csv": "camera.csv"},
     "illuminant": {"name": "LED-B4"} | {"csv": "led.csv"},
     "raw_to_xyz": "training" | "luther",
     "leds_mm": [[x, y, z], ...],        LED positions in the photometric camera's frame
     "led_intensity": 1.0,               relative, or one value per LED
     "centre_mm": [x, y, z],             dome centre in the same frame (E_ref reference)
     "exposure": kappa,                  image value per unit raw albedo at E_ref, ISO 100
     "iso_reference": 100,
     "polariser_transmission": 0.5,
     "shading": "leds" | "flat",         divide by the LED irradiance / specular lobe, or not
     "shadows": true,                    LEDs hidden by the face do not count
     "specular_exponent": 20}

This module imports :mod:`albedo_model` (``errors``, ``io.atomic``),
:mod:`pipeline.lightstage.colour` and :mod:`pipeline.texturing.json_files`;
:meth:`LightstageSpec.colour` imports :mod:`pipeline.lightstage.spectral_csv`.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from albedo_model.errors import FormatError, InputError
from albedo_model.io.atomic import atomic_path
from pipeline.lightstage.colour import (
    CameraColour,
    camera_colour,
    camera_colour_from_spectra,
    camera_sensitivities,
    illuminant_spd,
)
from pipeline.texturing.json_files import read_json_object

__all__ = [
    "FORMAT", "LightstageSpec", "SubjectEntry", "TemplateInfo", "list_subjects",
    "read_lightstage", "read_template", "read_vertex_mask", "write_json", "write_lightstage",
    "write_template",
]

FORMAT = "mcmcfit-lightstage"
VERSION = 1


def write_json(path: str | os.PathLike, data: Any) -> None:
    """Write JSON atomically (indented)."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=1) + "\n")


def _number(data: dict, key: str, path: Path, default: float | None = None) -> float:
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise FormatError(path, f"'{key}' must be a finite number, got {value!r}")
    return float(value)


@dataclasses.dataclass(frozen=True, eq=False)
class LightstageSpec:
    """The parsed ``lightstage.json`` (see the module notes)."""

    camera: dict
    illuminant: dict
    raw_to_xyz: str
    leds_mm: np.ndarray
    led_intensity: np.ndarray
    centre_mm: np.ndarray
    exposure: float
    iso_reference: float = 100.0
    polariser_transmission: float = 0.5
    shading: str = "leds"
    shadows: bool = True
    specular_exponent: float = 20.0
    folder: Path | None = None

    def to_json(self) -> dict:
        """Return the JSON object of this spec."""
        return {
            "format": FORMAT, "version": VERSION, "camera": self.camera,
            "illuminant": self.illuminant, "raw_to_xyz": self.raw_to_xyz,
            "leds_mm": np.round(self.leds_mm, 6).tolist(),
            "led_intensity": (float(self.led_intensity[0])
                              if np.all(self.led_intensity == self.led_intensity[0])
                              else self.led_intensity.tolist()),
            "centre_mm": self.centre_mm.tolist(), "exposure": self.exposure,
            "iso_reference": self.iso_reference,
            "polariser_transmission": self.polariser_transmission, "shading": self.shading,
            "shadows": self.shadows, "specular_exponent": self.specular_exponent,
        }

    def colour(self) -> CameraColour:
        """Return the calibrated camera (:class:`CameraColour`) the spec names."""
        from pipeline.lightstage.spectral_csv import read_spectral_csv

        base = self.folder or Path(".")
        method = self.raw_to_xyz
        if "csv" in self.camera:
            c = read_spectral_csv(base / self.camera["csv"], 3)
            cam_name = f"csv:{self.camera['csv']}"
        else:
            cam_name = self.camera["name"]
            c = camera_sensitivities(cam_name)
        if "csv" in self.illuminant:
            e = read_spectral_csv(base / self.illuminant["csv"], 1)[:, 0]
            ill_name = f"csv:{self.illuminant['csv']}"
        else:
            ill_name = self.illuminant["name"]
            e = illuminant_spd(ill_name)
        if "csv" not in self.camera and "csv" not in self.illuminant:
            return camera_colour(cam_name, ill_name, method=method)
        return camera_colour_from_spectra(c, e, camera=cam_name, illuminant_name=ill_name,
                                          method=method)


def _spectrum_ref(data: dict, key: str, path: Path) -> dict:
    ref = data.get(key)
    if not isinstance(ref, dict) or len(ref) != 1 or not isinstance(
            next(iter(ref.values())), str) or next(iter(ref)) not in ("name", "csv"):
        raise FormatError(path, f"'{key}' must be {{\"name\": ...}} or {{\"csv\": file}}")
    return dict(ref)


def read_lightstage(folder: str | os.PathLike) -> LightstageSpec:
    """Parse ``folder/lightstage.json``.

    Raises
    ------
    InputError, FormatError
        Missing file or malformed fields (the message names the file).
    """
    path = Path(folder) / "lightstage.json"
    data = read_json_object(path)
    if data.get("format") != FORMAT:
        raise FormatError(path, f"'format' must be {FORMAT!r}")
    try:
        leds = np.asarray(data.get("leds_mm"), float)
        centre = np.asarray(data.get("centre_mm"), float)
    except (TypeError, ValueError):
        raise FormatError(path, "'leds_mm' and 'centre_mm' must hold numbers") from None
    if leds.ndim != 2 or leds.shape[1] != 3 or len(leds) == 0 or not np.isfinite(leds).all():
        raise FormatError(path, "'leds_mm' must be a non-empty list of [x, y, z]")
    if centre.shape != (3,) or not np.isfinite(centre).all():
        raise FormatError(path, "'centre_mm' must be [x, y, z]")
    inten = data.get("led_intensity", 1.0)
    try:
        inten = np.broadcast_to(np.asarray(inten, float), (len(leds),)).copy()
    except (TypeError, ValueError):
        raise FormatError(path, "'led_intensity' must be a number or one per LED") from None
    shading = data.get("shading", "leds")
    if shading not in ("leds", "flat"):
        raise FormatError(path, "'shading' must be 'leds' or 'flat'")
    method = data.get("raw_to_xyz", "training")
    if method not in ("training", "luther"):
        raise FormatError(path, "'raw_to_xyz' must be 'training' or 'luther'")
    spec = LightstageSpec(
        camera=_spectrum_ref(data, "camera", path),
        illuminant=_spectrum_ref(data, "illuminant", path), raw_to_xyz=method,
        leds_mm=leds, led_intensity=inten, centre_mm=centre,
        exposure=_number(data, "exposure", path),
        iso_reference=_number(data, "iso_reference", path, 100.0),
        polariser_transmission=_number(data, "polariser_transmission", path, 0.5),
        shading=shading, shadows=bool(data.get("shadows", True)),
        specular_exponent=_number(data, "specular_exponent", path, 20.0),
        folder=Path(folder),
    )
    if not (spec.exposure > 0 and spec.iso_reference > 0 and spec.specular_exponent > 0
            and 0 < spec.polariser_transmission <= 1 and np.all(inten >= 0)):
        raise FormatError(path, "exposure, iso_reference, specular_exponent must be positive, "
                                "polariser_transmission in (0, 1], intensities >= 0")
    return spec


def write_lightstage(folder: str | os.PathLike, spec: LightstageSpec) -> None:
    """Write ``folder/lightstage.json``."""
    write_json(Path(folder) / "lightstage.json", spec.to_json())


@dataclasses.dataclass(frozen=True, eq=False)
class TemplateInfo:
    """What the build needs from the registration template."""

    vertices: np.ndarray
    triangles: np.ndarray
    symmetry: np.ndarray
    eyeballs: np.ndarray
    landmarks: dict[str, int]


def write_template(folder: str | os.PathLike, template: Any) -> None:
    """Write ``template.npz`` from a TemplateHead-like object.

    The object supplies vertices, triangles, symmetry, landmarks name -> index and
    regions with ``eyeballs``.
    """
    names = sorted(template.landmarks)
    eyes = np.asarray(template.regions.get("eyeballs", np.zeros(len(template.vertices), bool)))
    with atomic_path(Path(folder) / "template.npz") as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(
            fh, vertices=np.asarray(template.vertices, np.float64),
            triangles=np.asarray(template.triangles, np.int32),
            symmetry=np.asarray(template.symmetry, np.int64), eyeballs=eyes.astype(bool),
            landmark_names=np.array(names, dtype=str),
            landmark_indices=np.array([template.landmarks[k] for k in names], np.int64))


def read_template(folder: str | os.PathLike) -> TemplateInfo:
    """Read and check ``folder/template.npz``."""
    path = Path(folder) / "template.npz"
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    keys = ("vertices", "triangles", "symmetry", "eyeballs", "landmark_names",
            "landmark_indices")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in keys if k not in z]
            if missing:
                raise FormatError(path, f"missing arrays {', '.join(missing)}")
            a = {k: np.asarray(z[k]) for k in keys}
    except (OSError, ValueError) as exc:
        raise FormatError(path, f"not a readable npz file ({exc.__class__.__name__})") from None
    v, t, s = a["vertices"].astype(np.float64), a["triangles"], a["symmetry"]
    n = len(v)
    if v.ndim != 2 or v.shape[1] != 3 or t.ndim != 2 or t.shape[1] != 3:
        raise FormatError(path, "vertices must be (n, 3) and triangles (m, 3)")
    if t.min() < 0 or t.max() >= n or s.shape != (n,) or a["eyeballs"].shape != (n,):
        raise FormatError(path, "triangles, symmetry or eyeballs do not fit the vertices")
    if not np.array_equal(s[s], np.arange(n)):
        raise FormatError(path, "symmetry must be an involution")
    idx = a["landmark_indices"]
    if len(idx) != len(a["landmark_names"]) or (len(idx) and (idx.min() < 0 or idx.max() >= n)):
        raise FormatError(path, "landmark names and indices do not match the vertices")
    return TemplateInfo(v, t.astype(np.int32), s.astype(np.int64), a["eyeballs"].astype(bool),
                        {str(k): int(i) for k, i in zip(a["landmark_names"], idx)})


@dataclasses.dataclass(frozen=True)
class SubjectEntry:
    """One subject folder as described by its ``subject.json``."""

    subject_id: str
    folder: Path
    iso: float
    view_names: tuple[str, ...]
    parallel: tuple[Path, ...]
    perpendicular: tuple[Path, ...]
    cameras: Path
    registered: Path
    mask: Path | None
    truth: Path | None

    def input_files(self) -> list[Path]:
        """Every file the processing reads (for change detection)."""
        files = [self.folder / "subject.json", self.cameras, self.registered,
                 *self.parallel, *self.perpendicular]
        return files + ([self.mask] if self.mask is not None else [])


def _subject_entry(folder: Path) -> SubjectEntry:
    path = folder / "subject.json"
    data = read_json_object(path)
    views = data.get("views")
    if not isinstance(views, list) or not views:
        raise FormatError(path, "'views' must be a non-empty list")
    names, para, perp = [], [], []
    for i, view in enumerate(views):
        if not isinstance(view, dict) or not all(
                isinstance(view.get(k), str) for k in ("name", "parallel", "perpendicular")):
            raise FormatError(path, f"views[{i}] needs strings 'name', 'parallel', "
                                    "'perpendicular'")
        names.append(view["name"])
        para.append(folder / view["parallel"])
        perp.append(folder / view["perpendicular"])

    def optional(key: str) -> Path | None:
        value = data.get(key)
        if value is None:
            return None
        if not isinstance(value, str):
            raise FormatError(path, f"'{key}' must be a file name")
        return folder / value

    iso = _number(data, "iso", path, 100.0)
    if iso <= 0:
        raise FormatError(path, "'iso' must be positive")
    return SubjectEntry(folder.name, folder, iso, tuple(names), tuple(para), tuple(perp),
                        folder / data.get("cameras", "cameras.json"),
                        folder / data.get("registered", "registered.ply"),
                        optional("mask"), optional("truth"))


def list_subjects(folder: str | os.PathLike, kind: str = "subjects") -> list[SubjectEntry]:
    """Subject folders under ``folder/subjects`` (sorted by name) that hold a ``subject.json``."""
    root = Path(folder) / kind
    if not root.is_dir():
        return []
    return [_subject_entry(d) for d in sorted(root.iterdir())
            if d.is_dir() and (d / "subject.json").is_file()]


def read_vertex_mask(path: Path, n_vertices: int) -> np.ndarray:
    """(n,) bool from a text file of 0-based vertex indices (one per line, ``#`` comments)."""
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    idx = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        try:
            idx.append(int(text))
        except ValueError:
            raise FormatError(path, f"line {number}: not a vertex index") from None
    mask = np.zeros(n_vertices, bool)
    arr = np.array(idx, np.int64)
    if arr.size and (arr.min() < 0 or arr.max() >= n_vertices):
        raise FormatError(path, f"vertex indices must lie in [0, {n_vertices})")
    mask[arr] = True
    return mask
