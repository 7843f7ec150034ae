"""A joint fit as files: several photographs of one face in, one result folder out.

:func:`run_joint_fit_job` reads the photographs and their landmark files (or
detects the landmarks of each), fits them jointly
(:func:`mcmcfit.fitting.joint_fit.fit_joint`) and writes the result folder
atomically (:func:`mcmcfit.outputs.joint_folder.write_joint_outputs`): complete
or absent, nothing written when an input is bad. An unconverged fit warns as a
single fit does.

This module imports :mod:`albedo_model` (errors, io) and :mod:`mcmcfit.jobs.fit_job`;
the fit and the outputs are imported when a job runs.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.model_files import file_sha256
from mcmcfit.fitting.config import FitConfig
from mcmcfit.jobs.fit_job import (
    LoadedModel, _as_loaded, _check_out_dir, atomic_folder, check_landmark_names, read_landmarks,
    warn_if_unconverged,
)
from albedo_model.io.model_files import DEFAULT_FACE_MODEL

__all__ = ["joint_fit_into_folder", "run_joint_fit_job"]


def joint_fit_into_folder(images: list[np.ndarray], landmarks: list, loaded: LoadedModel,
                          out_dir: str | os.PathLike, *, config: FitConfig | None = None,
                          seed: int = 0, progress=None, force: bool = False,
                          inputs: list[dict] | None = None, truth=None) -> dict:
    """Fit arrays jointly and write the complete result folder atomically; return the summary."""
    from mcmcfit.fitting.joint_fit import fit_joint
    from mcmcfit.outputs.joint_folder import write_joint_outputs

    out = Path(out_dir)
    _check_out_dir(out, force)
    result = fit_joint(images, landmarks, loaded.model, config=config or FitConfig(), seed=seed,
                       progress=progress, model_uri=loaded.uri)
    with atomic_folder(out, force=force) as tmp:
        summary = write_joint_outputs(tmp, result, loaded, images, landmarks=landmarks,
                                      inputs=inputs, truth=truth)
    warn_if_unconverged(result.convergence, stacklevel=2)
    return summary


def run_joint_fit_job(image_paths: Sequence[str | os.PathLike], out_dir: str | os.PathLike, *,
                      landmarks_paths: Sequence[str | os.PathLike] | None = None,
                      model=DEFAULT_FACE_MODEL, config: FitConfig | None = None, seed: int = 0,
                      progress=None, force: bool = False, model_progress: bool = False,
                      face: int | None = None) -> dict:
    """Fit several photographs of one face jointly and write one result folder.

    Parameters
    ----------
    image_paths : sequence of path-like
        PNG or JPEG photographs (gamma-encoded sRGB), at least two.
    out_dir : path-like
    landmarks_paths : sequence of path-like or None, optional
        One ``.tlms`` / ``.pts`` file per photograph, in the same order; without
        them every photograph's landmarks are detected (the ``landmarks`` extra),
        and so are those of a photograph whose entry is None.
    model, config, seed, progress, force, model_progress, face
        As :func:`mcmcfit.jobs.fit_job.run_fit_job`.

    Returns
    -------
    dict
        The content of ``summary.json``.
    """
    from albedo_model.io.image_io import read_image

    out = Path(out_dir)
    _check_out_dir(out, force)
    paths = [Path(p) for p in image_paths]
    if landmarks_paths is not None and len(landmarks_paths) != len(paths):
        raise InputError(f"{len(paths)} photographs but {len(landmarks_paths)} landmark files: "
                         "give one per photograph, in the same order")
    images = [read_image(p) for p in paths]
    for p, im in zip(paths, images):
        if float(np.max(im)) < 0.5 / 255.0:
            raise InputError(f"{p}: the image is all black; there is no face to fit")
    loaded = _as_loaded(model, progress=model_progress)
    landmarks, inputs = [], []
    for i, (p, im) in enumerate(zip(paths, images)):
        if landmarks_paths is not None and landmarks_paths[i] is not None:
            lm = read_landmarks(landmarks_paths[i])
            source = str(landmarks_paths[i])
        else:
            from mcmcfit.detection.landmarks import detect_landmarks

            lm = detect_landmarks(im, face=face).landmarks
            source = "detected"
        check_landmark_names(lm, loaded.model, source=source)
        landmarks.append(lm)
        inputs.append({"image": str(p), "image_sha256": file_sha256(p),
                       "image_size": [int(im.shape[1]), int(im.shape[0])], "landmarks": source})
    return joint_fit_into_folder(images, landmarks, loaded, out, config=config, seed=seed,
                                 progress=progress, force=force, inputs=inputs)
