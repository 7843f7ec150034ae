"""Plan and run a batch: which images to fit, the engine, the journals, the progress bar.

:func:`plan_batch` finds the images (:mod:`mcmcfit.batch.discovery`), keeps
those whose result folder is not complete (or all of them with ``force``),
removes temporary folders left by a killed run, and builds one
:class:`~mcmcfit.batch.task.FitTask` per image; with ``group_by="person"``
one per person (:func:`mcmcfit.batch.discovery.group_by_person`), its
photographs fitted jointly into ``OUT/<person>/`` (a person with one usable
photograph gets a single fit there). :func:`run_batch` runs them on
the process pool or on Dask and, in this process only, appends one line per
finished image to ``OUT/batch.jsonl`` and one per failed or skipped image to
``OUT/failures.jsonl`` (:mod:`mcmcfit.batch.journal`).

A complete folder that has no ``batch.jsonl`` line (the batch was killed
between the rename and the journal write) gets its line on the next run,
marked ``"recovered": true``, so the journal ends with one line per result.

This module imports :mod:`mcmcfit.batch` modules, :mod:`mcmcfit.fitting.config`
(which loads JAX) and the standard library; tqdm is imported when a batch runs.
"""

from __future__ import annotations

import datetime
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

from albedo_model.errors import InputError
from albedo_model.io.model_files import BUILTIN_MODELS
from mcmcfit.batch.discovery import BatchItem, Skipped, discover, group_by_person
from mcmcfit.batch.journal import BATCH_JOURNAL, FAILURES_JOURNAL, append_line, read_journal
from mcmcfit.batch.out_paths import is_complete, remove_stale_temp_dirs, result_dir
from mcmcfit.batch.records import record_from_folder
from mcmcfit.batch.seeds import image_seed
from mcmcfit.batch.task import DETECT, FitTask, Photograph, run_task
from mcmcfit.fitting.config import FitConfig

__all__ = ["BatchOptions", "BatchPlan", "BatchResult", "plan_batch", "run_batch"]


@dataclass(frozen=True)
class BatchOptions:
    """What ``mcmcfit batch`` was asked to do.

    Attributes
    ----------
    input : Path
        Folder of images, or a text file listing them.
    out : Path
        Output folder.
    model : str
        Model file or ``"default"``.
    config : FitConfig
        Settings of every fit (the ray-casting threads are set from ``threads``;
        a worker with one thread runs the chains of its fit in its own process).
    seed : int
        Root seed; image seeds come from :func:`mcmcfit.batch.seeds.image_seed`.
    landmarks_dir, landmarks_glob : optional
        Where the landmarks are (:mod:`mcmcfit.batch.discovery`).
    face_box : str or None
        For images without landmarks: ``"lfw"`` or ``"x,y,w,h"``; None skips them.
    force : bool
        Refit images whose result folder is complete.
    workers : int
        Processes (pool or LocalCluster).
    threads : int
        Threads per worker.
    scheduler : str or None
        Dask scheduler address.
    dask : bool
        Use a Dask LocalCluster instead of the process pool.
    pin : bool
        Pin pool workers to cores.
    progress : bool
        Show the progress bar.
    model_colour : {"linear", "srgb"} or None
        The model's colour space (``--model-colour``): set in every fit's config
        (``FitConfig.model_colour``); None keeps the config's (by default read
        from the model).
    group_by : {None, "person"}
        ``"person"``: fit each person's photographs jointly (one result folder
        per person; needs landmarks, files or detected, not a face box).
    max_per_person : int
        With ``group_by``: the photographs of a person fitted together (2-8;
        the rest are skipped with the reason).
    """

    input: Path
    out: Path
    model: str = "default-face"
    config: FitConfig = field(default_factory=FitConfig)
    seed: int = 0
    landmarks_dir: Path | None = None
    landmarks_glob: str | None = None
    face_box: str | None = None
    force: bool = False
    workers: int = 1
    threads: int = 1
    scheduler: str | None = None
    dask: bool = False
    pin: bool = False
    progress: bool = True
    model_colour: str | None = None
    group_by: str | None = None
    max_per_person: int = 4

    def __post_init__(self) -> None:
        """Refuse options a joint fit cannot take (:class:`~albedo_model.errors.InputError`)."""
        if self.group_by not in (None, "person"):
            raise InputError(f"group_by must be None or 'person', got {self.group_by!r}")
        if self.group_by and not 2 <= self.max_per_person <= 8:
            raise InputError(f"--max-per-person must be 2 to 8 (a joint fit's photographs), "
                             f"got {self.max_per_person}")
        if self.group_by and self.face_box not in (None, DETECT):
            raise InputError("--group-by person fits photographs jointly, which needs "
                             "landmarks (files or --detect-landmarks), not a face box")


@dataclass
class BatchPlan:
    """The tasks to run, the images already complete and those skipped."""

    tasks: list[FitTask]
    complete: list[BatchItem]
    skipped: list[Skipped]


@dataclass
class BatchResult:
    """Counts of one run of a batch (``failed`` lists the outcomes of failed images)."""

    total: int
    already_complete: int
    fitted: int
    failed: list[dict]
    skipped: int
    unconverged: int = 0

    @property
    def exit_code(self) -> int:
        """0 when no image failed in this run, else 1."""
        return 1 if self.failed else 0


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def _model_spec(spec: str) -> str:
    if str(spec) in BUILTIN_MODELS:  # built-in names, resolved by each worker
        return str(spec)
    return os.path.abspath(spec)


def plan_batch(opts: BatchOptions) -> BatchPlan:
    """Images to fit now, images already complete, images skipped (see the module docstring)."""
    out = Path(opts.out)
    items, skipped = discover(opts.input, exclude=[out], landmarks_dir=opts.landmarks_dir,
                              landmarks_glob=opts.landmarks_glob,
                              allow_face_box=opts.face_box is not None)
    # a worker with one thread runs its chains one after the other: the batch's
    # processes already fill the cores (chains in parallel would oversubscribe them)
    colour = opts.config.model_colour if opts.model_colour is None else opts.model_colour
    config = opts.config.replace(threads=min(2, max(1, opts.threads)),
                                 parallel=opts.config.parallel and opts.threads > 1,
                                 model_colour=colour)
    tasks, complete = [], []
    model = _model_spec(opts.model)
    common = {"model": model, "config": config.to_dict(), "threads": max(1, opts.threads)}
    if opts.group_by:
        groups, extra = group_by_person(items, max_per_person=opts.max_per_person)
        skipped = skipped + extra
        units = [(g.relative, g.items) for g in groups]
    else:
        units = [(item.relative, (item,)) for item in items]
    for relative, members in units:
        folder = result_dir(out, relative)
        first = members[0]
        source = str(relative) if opts.group_by else first.source
        if is_complete(folder) and not opts.force:
            complete.append(BatchItem(first.image, source, relative, first.landmarks))
            continue
        joint = tuple(Photograph(str(m.image), m.source, None if m.landmarks is None
                                 else str(m.landmarks.absolute())) for m in members)
        tasks.append(FitTask(
            image=str(first.image), source=source, relative=str(relative),
            out_dir=str(folder.absolute()), landmarks=joint[0].landmarks,
            face_box=None if first.landmarks is not None else opts.face_box,
            seed=image_seed(opts.seed, relative), force=opts.force or folder.exists(),
            members=joint if opts.group_by else (), **common))
    return BatchPlan(tasks, complete, skipped)


def _journal_missing(out: Path, complete: list[BatchItem], run_id: str) -> None:
    known = {r.get("relative") for r in read_journal(out / BATCH_JOURNAL)
             if r.get("status") == "ok"}
    for item in complete:
        if str(item.relative) in known:
            continue
        folder = result_dir(out, item.relative)
        try:
            record = record_from_folder(folder)
        except (OSError, ValueError, KeyError) as exc:
            record = {"note": f"summary unreadable: {exc}"}
        append_line(out / BATCH_JOURNAL, {"path": item.source, "relative": str(item.relative),
                                          "status": "ok", "recovered": True, "run": run_id,
                                          "finished_at": _now(), **record})


def _journal_skipped(out: Path, skipped: list[Skipped], run_id: str) -> None:
    last = {r.get("path"): r for r in read_journal(out / FAILURES_JOURNAL)}
    for s in skipped:
        prev = last.get(s.source)
        if prev is not None and prev.get("status") == "skipped" and prev.get("reason") == s.reason:
            continue
        append_line(out / FAILURES_JOURNAL, {"path": s.source, "relative": s.relative,
                                             "status": "skipped", "reason": s.reason,
                                             "run": run_id, "finished_at": _now()})


def _outcomes(opts: BatchOptions, tasks: list[FitTask], fn):
    if opts.scheduler or opts.dask:
        from mcmcfit.batch.dask_runner import dask_outcomes

        return dask_outcomes(tasks, scheduler=opts.scheduler, workers=opts.workers,
                             threads=opts.threads, fn=fn)
    from mcmcfit.batch.pool_runner import pool_outcomes

    return pool_outcomes(tasks, workers=opts.workers, threads=opts.threads, pin=opts.pin, fn=fn)


def run_batch(opts: BatchOptions, *, log=None, task_fn=run_task) -> BatchResult:
    """Fit every image of the batch that is not complete yet; journal every outcome.

    Parameters
    ----------
    opts : BatchOptions
    log : callable ``(str) -> None``, optional
        Receives a few lines about the plan (default: stderr).
    task_fn : callable ``(FitTask) -> dict``
        The task function (module-level); :func:`mcmcfit.batch.task.run_task`.

    Returns
    -------
    BatchResult
    """
    from tqdm import tqdm

    log = log or (lambda text: print(text, file=sys.stderr))
    out = Path(opts.out)
    out.mkdir(parents=True, exist_ok=True)
    run_id = f"{datetime.datetime.now():%Y%m%dT%H%M%S}-{os.getpid()}"
    plan = plan_batch(opts)
    _journal_missing(out, plan.complete, run_id)
    _journal_skipped(out, plan.skipped, run_id)
    for task in plan.tasks:
        remove_stale_temp_dirs(task.out_dir)
    total = len(plan.tasks) + len(plan.complete)
    joint = sum(len(t.members) > 1 for t in plan.tasks)
    log(f"mcmcfit batch: {total} {'people' if opts.group_by else 'images'}, "
        f"{len(plan.complete)} already complete, {len(plan.tasks)} to fit"
        + (f" ({joint} jointly)" if opts.group_by else "")
        + f", {len(plan.skipped)} skipped" + (" (see failures.jsonl)" if plan.skipped else ""))
    failed: list[dict] = []
    fitted = unconverged = 0
    bar = tqdm(total=len(plan.tasks), unit="person" if opts.group_by else "img", desc="fitting", file=sys.stderr,
               disable=not opts.progress or not plan.tasks, dynamic_ncols=True)
    try:
        bar.set_postfix_str(f"done=0 failed=0 remaining={len(plan.tasks)}")
        for outcome in _outcomes(opts, plan.tasks, task_fn):
            record = {**outcome, "run": run_id, "finished_at": _now()}
            if outcome.get("status") == "ok":
                fitted += 1
                unconverged += outcome.get("converged") is False
                append_line(out / BATCH_JOURNAL, record)
            else:
                failed.append(record)
                append_line(out / FAILURES_JOURNAL, record)
            bar.update(1)
            remaining = len(plan.tasks) - fitted - len(failed)
            bar.set_postfix_str(f"done={fitted} failed={len(failed)} remaining={remaining}")
    finally:
        bar.close()
    return BatchResult(total, len(plan.complete), fitted, failed, len(plan.skipped), unconverged)
