"""One task of a batch: fit one image (or one person's photographs) into its result folder, never raise.

:class:`FitTask` holds only plain values, so it pickles to a spawned process
or a Dask worker. :func:`run_task` runs :func:`mcmcfit.jobs.fit_job.run_fit_job`
(imported inside the task, after the worker's thread limits are in place) and
returns an outcome dict (a task with ``members``, one person's photographs
under ``batch --group-by person``, runs
:func:`mcmcfit.jobs.joint_job.run_joint_fit_job` instead); every exception becomes a ``"failed"`` outcome with a
one-line reason, so one bad image never stops the batch. The worker writes the
image's result folder (atomically); the journals are written by the batch's
parent process from the outcomes.

This module imports :mod:`mcmcfit.batch` modules; :mod:`albedo_model.errors`,
:mod:`mcmcfit.fitting.config` and :mod:`mcmcfit.jobs.fit_job` are imported
when a task runs.
"""

from __future__ import annotations

import os
import socket
import time
import traceback
import warnings
from dataclasses import asdict, dataclass

from mcmcfit.batch.face_boxes import lfw_face_box
from mcmcfit.batch.records import finished_record
from mcmcfit.batch.worker_env import apply_thread_env, thread_env

__all__ = ["DETECT", "FitTask", "LFW_BOX", "Photograph", "run_task"]

#: ``FitTask.face_box`` value meaning "the LFW default box scaled to the image".
LFW_BOX = "lfw"
#: ``FitTask.face_box`` value meaning "detect the landmarks" (``batch --detect-landmarks``).
DETECT = "detect"


@dataclass(frozen=True)
class Photograph:
    """One photograph of a joint task (plain, picklable values).

    Attributes
    ----------
    image : str
        Absolute image path.
    source : str
        The image as named in the input.
    landmarks : str or None
        Landmark file; None detects the landmarks (``batch --detect-landmarks``).
    """

    image: str
    source: str
    landmarks: str | None


@dataclass(frozen=True)
class FitTask:
    """Everything a worker needs to fit one image (plain, picklable values).

    Attributes
    ----------
    image : str
        Absolute image path (on shared storage for a Dask cluster).
    source : str
        The image as named in the input (journals).
    relative : str
        Relative output path (``Name/Name_0001``).
    out_dir : str
        Absolute result folder.
    landmarks : str or None
        Landmark file; None fits with ``face_box``.
    face_box : str or None
        ``"lfw"`` (:func:`mcmcfit.batch.face_boxes.lfw_face_box`), ``"x,y,w,h"``,
        ``"detect"`` (detect the landmarks, :data:`DETECT`), or None.
    model : str
        Model file path (or ``"default"``).
    config : dict
        :meth:`mcmcfit.fitting.config.FitConfig.to_dict`.
    seed : int
        The image's seed (:func:`mcmcfit.batch.seeds.image_seed`).
    force : bool
        Replace an existing result folder.
    threads : int
        Thread limit applied when the worker has not loaded JAX yet.
    members : tuple of Photograph
        Empty for one image; under ``batch --group-by person`` the photographs
        of one person, fitted jointly when there are several (``image`` and
        ``landmarks`` then are the first photograph's, ``source`` the person).
    """

    image: str
    source: str
    relative: str
    out_dir: str
    landmarks: str | None
    face_box: str | None
    model: str
    config: dict
    seed: int
    force: bool = False
    threads: int = 1
    members: tuple[Photograph, ...] = ()

    def to_dict(self) -> dict:
        """Return the fields as a plain dict."""
        return asdict(self)


def _image_size(path: str) -> tuple[int, int] | None:
    from PIL import Image

    try:
        with Image.open(path) as im:
            return im.size
    except Exception:  # unreadable: run_fit_job reports it with a proper message
        return None


def _face_box_xywh(task: FitTask):
    if task.landmarks is not None or task.face_box in (None, DETECT):
        return None
    if task.face_box != LFW_BOX:
        return task.face_box
    size = _image_size(task.image)
    if size is None:
        return None
    x0, y0, x1, y1 = lfw_face_box(*size)
    return (x0, y0, x1 - x0, y1 - y0)


def _reason(exc: BaseException) -> str:
    from albedo_model.errors import AlbedoModelError

    text = " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, AlbedoModelError):
        return text
    frames = traceback.extract_tb(exc.__traceback__)
    where = f" (at {os.path.basename(frames[-1].filename)}:{frames[-1].lineno})" if frames else ""
    return f"{type(exc).__name__}: {text}{where}"


def _run(task: FitTask) -> dict:
    """Run the task's fit job; return its summary."""
    from mcmcfit.fitting.config import FitConfig

    config = FitConfig.from_dict(task.config)
    if len(task.members) > 1:
        from mcmcfit.jobs.joint_job import run_joint_fit_job

        return run_joint_fit_job([m.image for m in task.members], task.out_dir,
                                 landmarks_paths=[m.landmarks for m in task.members],
                                 model=task.model, config=config, seed=task.seed,
                                 force=task.force)
    from mcmcfit.jobs.fit_job import run_fit_job

    return run_fit_job(task.image, task.out_dir, landmarks_path=task.landmarks,
                       face_box=_face_box_xywh(task), model=task.model, config=config,
                       seed=task.seed, force=task.force,
                       detect=task.landmarks is None and task.face_box == DETECT)


def run_task(task: FitTask) -> dict:
    """Fit one image; return an outcome dict (never raises for a failing image).

    Returns
    -------
    dict
        ``status`` ("ok" or "failed"), ``path`` (source), ``relative``,
        ``seconds``, ``seed``, ``host``, ``pid`` (and ``images``, the
        photographs' sources, for a person's task); for "ok" the journal fields of
        :func:`mcmcfit.batch.records.finished_record` and ``warnings`` (when
        the fit warned); for "failed" ``reason`` and ``error_type``.
    """
    apply_thread_env(thread_env(task.threads), override=False)
    t0 = time.perf_counter()
    base = {"path": task.source, "relative": task.relative, "seed": task.seed,
            "host": socket.gethostname(), "pid": os.getpid()}
    if task.members:
        base["images"] = [m.source for m in task.members]
    try:
        # warnings go into the journal instead of interleaving with the progress bar
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UserWarning)
            summary = _run(task)
    except Exception as exc:  # any failure of one image is recorded, the batch goes on
        return {**base, "status": "failed", "seconds": time.perf_counter() - t0,
                "reason": _reason(exc), "error_type": type(exc).__name__}
    notes = sorted({str(w.message) for w in caught if issubclass(w.category, UserWarning)})
    try:
        record = finished_record(summary, task.out_dir)
    except Exception as exc:  # the result folder is complete; only its digest is missing
        record = {"note": f"journal fields unavailable: {_reason(exc)}"}
    return {**base, "status": "ok", "seconds": time.perf_counter() - t0, **record,
            **({"warnings": notes} if notes else {})}
