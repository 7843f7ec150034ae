"""One fit job: image (+ landmarks | face box) on disk -> a complete result folder.

:func:`run_fit_job` reads the inputs, runs :func:`mcmcfit.fitting.fit.fit`, writes every
output (:mod:`mcmcfit.outputs`) into a temporary sibling folder and renames it
onto ``out_dir``: a result folder is complete or absent, never partial. Bad
input raises :class:`~albedo_model.errors.InputError` (or ``FormatError``)
before anything is written. Its arguments are plain picklable values, so a
process pool can run it; models are loaded once per process
(:func:`load_model_cached`).

This module imports :mod:`albedo_model`, :mod:`mcmcfit.fitting`, :mod:`mcmcfit.outputs`
and :mod:`mcmcfit.jobs.model_spec` (and through it :mod:`pipeline.synthetic.default_model`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.model_files import (
    BUILTIN_MODELS, DEFAULT_FACE_MODEL, DEFAULT_MODEL, file_sha256,
)
from albedo_model.model import MorphableModel
from mcmcfit.fitting.config import FitConfig

__all__ = ["FitWarning", "LoadedModel", "load_model_cached", "read_landmarks", "parse_face_box",
           "warn_if_unconverged",
           "check_landmark_names",
           "run_fit_job", "fit_into_folder", "atomic_folder"]


class FitWarning(UserWarning):
    """Something about the inputs the user should know; the fit goes on (e.g. unknown names)."""


class LoadedModel(NamedTuple):
    """A model with what results record about it.

    Attributes
    ----------
    model : MorphableModel
    sha256 : str
        Hex SHA-256 of the model file ("" when the model did not come from a file).
    uri : str
        Written into the parameters' ``momo.model_uri`` (the file path, or "default").
    """

    model: MorphableModel
    sha256: str = ""
    uri: str = ""


_CACHE: dict[tuple, LoadedModel] = {}


def load_model_cached(spec: str | os.PathLike = DEFAULT_MODEL, *,
                      progress: bool = False) -> LoadedModel:
    """Load the model named by ``spec`` (a path or ``"default"``) once per process.

    The cache key is the resolved file with its size and modification time, so a
    rebuilt or replaced file is loaded again.
    """
    from mcmcfit.jobs.model_spec import resolve_model

    path = Path(resolve_model(str(spec), progress=progress)).resolve()
    st = path.stat()
    key = (str(path), st.st_size, st.st_mtime_ns)
    if key not in _CACHE:
        from albedo_model.io.model_files import load_model

        uri = str(spec) if str(spec) in BUILTIN_MODELS else str(path)
        _CACHE.clear()  # one model per worker process is the common case; bound the memory
        _CACHE[key] = LoadedModel(load_model(path), file_sha256(path), uri)
    return _CACHE[key]


def _as_loaded(model, *, progress: bool = False) -> LoadedModel:
    if isinstance(model, LoadedModel):
        return model
    if isinstance(model, MorphableModel):
        return LoadedModel(model, "", "")
    if isinstance(model, tuple) and model and isinstance(model[0], MorphableModel):
        return LoadedModel(*model)
    if isinstance(model, (str, os.PathLike)):
        return load_model_cached(model, progress=progress)
    raise InputError(f"model must be a path, 'default' or a loaded model, got {type(model).__name__}")


def read_landmarks(path: str | os.PathLike) -> list:
    """2-D landmarks from a ``.tlms`` file or an iBUG 68-point ``.pts`` file.

    Returns
    -------
    list of albedo_model.io.tlms.Landmark
        For ``.pts`` only the points with a Basel name (see :mod:`albedo_model.io.pts`).

    Raises
    ------
    InputError
        Missing file, unknown suffix or 3-D landmarks.
    FormatError
        Malformed file.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: landmark file not found")
    suffix = p.suffix.lower()
    if suffix == ".tlms":
        from albedo_model.io.tlms import read_tlms

        lms = read_tlms(p)
        if lms and lms[0].dim != 2:
            raise InputError(f"{p}: 3-D landmarks; a fit needs 2-D pixel landmarks")
        return lms
    if suffix == ".pts":
        from albedo_model.io.pts import pts_to_landmarks, read_pts

        return pts_to_landmarks(read_pts(p))
    raise InputError(f"{p}: unknown landmark file type {p.suffix!r} (expected .tlms or .pts)")


def parse_face_box(box) -> tuple[float, float, float, float]:
    """Convert ``"x,y,w,h"`` or a 4-sequence (x, y, w, h) to ``(x0, y0, x1, y1)``.

    The result is the face box as :func:`mcmcfit.fitting.fit.fit` takes it.
    """
    if isinstance(box, str):
        try:
            vals = [float(v) for v in box.replace(" ", "").split(",")]
        except ValueError:
            raise InputError(f"face box must be x,y,w,h numbers, got {box!r}") from None
    else:
        vals = [float(v) for v in box]
    if len(vals) != 4 or not all(np.isfinite(vals)) or vals[2] <= 0 or vals[3] <= 0:
        raise InputError(f"face box must be x,y,w,h with w, h > 0, got {box!r}")
    x, y, w, h = vals
    return (x, y, x + w, y + h)


@contextlib.contextmanager
def atomic_folder(out_dir: str | os.PathLike, *, force: bool = False):
    """Yield a fresh temporary sibling folder; rename it onto ``out_dir`` on success.

    On an exception the temporary folder is removed and ``out_dir`` is left as it
    was. With ``force`` an existing ``out_dir`` is replaced (moved aside, then
    deleted after the rename); without it an existing ``out_dir`` is an error.
    """
    final = Path(out_dir)
    if final.exists() and not force:
        raise InputError(f"{final}: output folder exists (use --force to replace it)")
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.partial-", dir=final.parent))
    try:
        yield tmp
        _publish_permissions(tmp)
        old = None
        if final.exists():
            if not force:
                raise InputError(f"{final}: output folder appeared during the fit")
            old = Path(tempfile.mkdtemp(prefix=f".{final.name}.old-", dir=final.parent))
            os.replace(final, old / "previous")
        os.replace(tmp, final)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def _publish_permissions(folder: Path) -> None:
    """Give the folder and its files the umask's permissions (temporary names are private)."""
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(folder, 0o777 & ~mask)
    for p in folder.rglob("*"):
        os.chmod(p, (0o777 if p.is_dir() else 0o666) & ~mask)


def _check_out_dir(out_dir: Path, force: bool) -> None:
    if out_dir.exists() and not force:
        raise InputError(f"{out_dir}: output folder exists (use --force to replace it)")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"{out_dir}: exists and is not a folder")


def fit_into_folder(image: np.ndarray, landmarks, loaded: LoadedModel, out_dir: str | os.PathLike,
                    *, config: FitConfig | None = None, seed: int = 0, face_box=None,
                    progress=None, force: bool = False, inputs: dict | None = None,
                    truth=None, before_write=None, landmark_sigma=None) -> dict:
    """Fit arrays and write the complete result folder atomically (the core of the jobs).

    Parameters
    ----------
    image : (H, W, 3) float in [0, 1], gamma-encoded
    landmarks : list of Landmark, mapping name -> (x, y), or None
    loaded : LoadedModel
    out_dir : path-like
    config : FitConfig, optional
    seed : int
    face_box : (x0, y0, x1, y1), optional
    progress : callable ``(stage, chain, done, total)``, optional
    force : bool
        Replace an existing ``out_dir``.
    inputs : dict, optional
        Recorded under ``"inputs"`` in ``summary.json`` (paths, sizes).
    truth : mcmcfit.outputs.truth.Truth, optional
        Ground truth of a synthetic case; adds the albedo error to the summary and report.
    before_write : callable ``(folder: Path) -> None``, optional
        Writes extra files into the temporary folder first (e.g. the demo's truth).
    landmark_sigma : mapping name -> float, optional
        Per-landmark factors of the landmark noise (detected landmarks).

    Returns
    -------
    dict
        The ``summary.json`` content.
    """
    from mcmcfit.fitting.fit import fit
    from mcmcfit.outputs import write_fit_outputs

    out = Path(out_dir)
    _check_out_dir(out, force)
    cfg = config or FitConfig()
    result = fit(image, landmarks, loaded.model, config=cfg, seed=seed, progress=progress,
                 face_box=face_box, model_uri=loaded.uri, landmark_sigma=landmark_sigma)
    with atomic_folder(out, force=force) as tmp:
        if before_write is not None:
            before_write(tmp)
        summary = write_fit_outputs(tmp, result, loaded, image, landmarks=landmarks,
                                    face_box=face_box, inputs=inputs or {}, truth=truth)
    warn_if_unconverged(result.convergence, stacklevel=2)
    return summary


def warn_if_unconverged(conv: dict, *, stacklevel: int = 2) -> None:
    """Warn (:class:`FitWarning`) when a fit's convergence verdict says it has not converged."""
    if conv and not conv.get("converged"):
        worst = conv.get("worst") or [{}]
        warnings.warn(
            f"the chains have NOT converged (max R-hat {conv.get('max_rhat', float('nan')):.3g}, "
            f"min bulk-ESS {conv.get('min_ess_bulk', float('nan')):.0f}, worst "
            f"{worst[0].get('name', '?')}): the intervals and uncertainty maps show an unconverged "
            "walk, not the posterior (summary.json 'converged': false)", FitWarning,
            stacklevel=stacklevel + 1)


def check_landmark_names(landmarks, model: MorphableModel, *, source="landmarks",
                         minimum: int = 3) -> None:
    """Raise InputError when fewer than ``minimum`` visible landmarks have known names.

    A name is known when the model has a landmark of that name.
    """
    if isinstance(landmarks, dict):
        names = list(landmarks)
    else:
        names = [lm.name for lm in landmarks if lm.visible]
    known = [n for n in names if n in model.landmark_vertices]
    if len(known) < minimum:
        raise InputError(f"{source}: only {len(known)} visible landmark(s) with a name the model "
                         f"knows (need at least {minimum})")


def run_fit_job(image_path: str | os.PathLike, out_dir: str | os.PathLike, *,
                landmarks_path: str | os.PathLike | None = None, face_box=None,
                model=DEFAULT_FACE_MODEL, config: FitConfig | None = None, seed: int = 0,
                progress=None, force: bool = False, model_progress: bool = False,
                detect: bool = True, face: int | None = None) -> dict:
    """Fit one image file and write its result folder (complete or not at all).

    Parameters
    ----------
    image_path : path-like
        PNG or JPEG photograph (gamma-encoded sRGB).
    out_dir : path-like
        Result folder to create (see the README for its files).
    landmarks_path : path-like, optional
        ``.tlms`` or iBUG ``.pts`` 2-D landmarks.
    face_box : "x,y,w,h" or (x, y, w, h), optional
        Used when there are no landmarks.
    detect : bool
        With neither landmarks nor a face box, detect the landmarks
        (:func:`mcmcfit.detection.landmarks.detect_landmarks`, the ``landmarks``
        extra): they and a picture of them are written to the result folder
        (``landmarks_detected.tlms``, ``landmarks_detected.png``) and described in
        ``summary.json`` (``inputs.landmark_detection``). False: start from a
        frontal face in the middle of the image, with a warning.
    face : int, optional
        Which detected face when there are several (0: the largest).
    model : str, path-like, LoadedModel or MorphableModel
        ``"default-face"`` (the default for photographs: the face-only crop of the
        built-in model, so that skin albedo is not asked to explain hair),
        ``"default"`` (the whole head), a model file, or an already loaded model
        (then its SHA-256 and URI come from the :class:`LoadedModel`).
    config : FitConfig, optional
    seed : int
    progress : callable ``(stage, chain, done, total)``, optional
    force : bool
        Replace an existing ``out_dir``.
    model_progress : bool
        Show progress when the default model has to be built first.

    Returns
    -------
    dict
        The content of ``summary.json``.

    Raises
    ------
    InputError, FormatError
        Unreadable or unusable inputs, or ``out_dir`` exists without ``force``;
        nothing is written then.
    """
    from albedo_model.io.image_io import read_image

    out = Path(out_dir)
    _check_out_dir(out, force)
    image = read_image(image_path)
    if float(np.max(image)) < 0.5 / 255.0:
        raise InputError(f"{image_path}: the image is all black; there is no face to fit")
    landmarks = read_landmarks(landmarks_path) if landmarks_path is not None else None
    box = parse_face_box(face_box) if face_box is not None else None
    detection = None
    if landmarks is None and box is None:
        if detect:
            from mcmcfit.fitting.initialisation import check_fit_inputs

            check_fit_inputs(image.shape[1], image.shape[0])  # a 1x1 PNG fails here, not later
            from mcmcfit.detection.landmarks import detect_landmarks

            detection = detect_landmarks(image, face=face)
            landmarks = detection.landmarks
        else:
            warnings.warn("no landmarks and no face box: the fit starts from a frontal face in "
                          "the middle of the image", FitWarning, stacklevel=2)
    loaded = _as_loaded(model, progress=model_progress)
    if landmarks is not None:
        check_landmark_names(landmarks, loaded.model,
                             source="detected landmarks" if detection else landmarks_path)
    inputs = {"image": str(image_path), "image_sha256": file_sha256(image_path),
              "image_size": [int(image.shape[1]), int(image.shape[0])],
              "landmarks": ("detected" if detection is not None else
                            None if landmarks_path is None else str(landmarks_path)),
              "face_box_xywh": None if box is None else
              [box[0], box[1], box[2] - box[0], box[3] - box[1]]}
    if detection is not None:
        inputs["landmark_detection"] = detection.summary()
        if detection.low_confidence:
            warnings.warn(f"detected landmarks are low confidence (yaw {detection.yaw_deg:+.0f} "
                          "deg, near profile): check landmarks_detected.png", FitWarning,
                          stacklevel=2)
    return fit_into_folder(image, landmarks, loaded, out, config=config, seed=seed,
                           face_box=box, progress=progress, force=force, inputs=inputs,
                           before_write=None if detection is None else
                           _detection_writer(image, detection),
                           landmark_sigma=None if detection is None else detection.sigma_factors)


def _detection_writer(image: np.ndarray, detection):
    """Return the ``before_write`` hook that puts the detected landmarks into the folder."""
    def write(folder: Path) -> None:
        from albedo_model.io.tlms import write_tlms
        from mcmcfit.detection.overlay import landmarks_png

        write_tlms(folder / "landmarks_detected.tlms", detection.landmarks)
        landmarks_png(image, detection.points(), folder / "landmarks_detected.png",
                      mesh=detection.mesh, box=detection.box, title=f"detected landmarks: face {detection.face} of "
                      f"{detection.n_faces}, yaw {detection.yaw_deg:+.0f} deg")
    return write
