"""Run an evaluation: cases, one batch per model, scores, table, plots, report.

:func:`run_evaluation` makes (or reuses) the cases
(:func:`mcmcfit.evaluation.cases.prepare_cases`), fits every photograph with
every model through the batch engine (:func:`mcmcfit.batch.run.run_batch`:
``EVAL/fits/<model>/<scene>/<subject>/``, resumable, failures in
``EVAL/fits/<model>/failures.jsonl``; the process pool, a Dask LocalCluster
or a running scheduler), scores every complete result folder
(:func:`mcmcfit.evaluation.score_fit.score_fit`) and writes::

    EVAL/results.json   settings, software, models, one row per case and model, the table
    EVAL/table.md       the paper's Table 1 per scene, then every score (mean +- sd)
    EVAL/table.csv      one row per scene and model
    EVAL/calibration.png, EVAL/accuracy_time.png, EVAL/report.html

each atomically. With ``score_only`` nothing is fitted: the existing result
folders are scored again.

This module imports :mod:`albedo_model.errors`, :mod:`mcmcfit.evaluation`
modules and, when it runs, :mod:`mcmcfit.batch.run` and :mod:`albedo_model.io`.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from albedo_model.errors import InputError
from mcmcfit.evaluation.cases import MODEL_VARIANTS, case_settings, load_cases, prepare_cases

__all__ = ["EvaluateOptions", "run_evaluation", "score_all"]


@dataclass(frozen=True)
class EvaluateOptions:
    """What ``mcmcfit evaluate`` was asked to do.

    Attributes
    ----------
    out : Path
        The evaluation folder ``EVAL``.
    n_subjects, n_held_out : int
        Training and held-out subjects.
    scenes, models : tuple of str
        Scene names (:data:`pipeline.synthetic.scenes.SCENES`) and model variants
        (:data:`mcmcfit.evaluation.cases.MODEL_VARIANTS`).
    size : int
        Image width and height.
    seed : int
        Root seed of the fits (each case's seed derives from it and its path).
    population_seed : int
        Seed of the population (subjects, detail, scenes).
    detail : dict
        :class:`pipeline.synthetic.skin_detail.SkinDetail` fields.
    config : FitConfig or None
        Settings of every fit (the model's colour space is set per model).
    workers, threads : int
        Batch processes and threads per process.
    dask : bool
    scheduler : str or None
    score_only : bool
        Score the existing result folders, fit nothing.
    force : bool
        Refit cases whose result folder is complete.
    progress : bool
    """

    out: Path
    n_subjects: int = 60
    n_held_out: int = 6
    scenes: tuple = ("ambient", "directional")
    models: tuple = ("intrinsic", "baked", "baked-gamma")
    size: int = 250
    seed: int = 0
    population_seed: int = 2020
    detail: dict = field(default_factory=dict)
    config: object = None
    workers: int = 1
    threads: int = 1
    dask: bool = False
    scheduler: str | None = None
    score_only: bool = False
    force: bool = False
    progress: bool = True


def _fit_models(opts: EvaluateOptions, cases: dict, log) -> dict:
    from mcmcfit.batch.run import BatchOptions, run_batch
    from mcmcfit.fitting.config import FitConfig

    root = Path(opts.out)
    base = opts.config or FitConfig()
    counts = {}
    for name in opts.models:
        rec = cases["models"][name]
        log(f"mcmcfit evaluate: fitting with the {name} model ({rec['label']})")
        result = run_batch(BatchOptions(
            input=root / "cases", out=root / "fits" / name, model=str(root / rec["file"]),
            config=base.replace(model_colour=rec["model_colour"]), seed=opts.seed,
            workers=opts.workers, threads=opts.threads, dask=opts.dask,
            scheduler=opts.scheduler, force=opts.force, progress=opts.progress), log=log)
        counts[name] = {"fitted": result.fitted, "failed": len(result.failed),
                        "already_complete": result.already_complete}
    return counts


def _failure_reasons(folder: Path) -> dict[str, str]:
    from mcmcfit.batch.journal import FAILURES_JOURNAL, read_journal

    return {r.get("relative"): r.get("reason", r.get("status"))
            for r in read_journal(folder / FAILURES_JOURNAL)}


def score_all(root: Path, cases: dict, models: tuple) -> tuple[list[dict], dict]:
    """Score every case with every model; return the rows and the loaded models.

    A case without a complete result folder gives a row with ``status``
    ``"failed"`` and the reason from the batch's ``failures.jsonl``, or
    ``"missing"`` when the batch has not fitted it (yet).
    """
    from albedo_model.io.model_files import load_model
    from albedo_model.regions import face_regions
    from mcmcfit.evaluation.score_fit import score_fit

    root = Path(root)
    loaded = {name: load_model(root / cases["models"][name]["file"]) for name in models}
    regions = face_regions(next(iter(loaded.values())))
    rows = []
    for name in models:
        fits = root / "fits" / name
        reasons = _failure_reasons(fits) if fits.is_dir() else {}
        colour = cases["models"][name]["model_colour"]
        for case in cases["cases"]:
            fit_dir = fits / case["case"]
            base = {k: case[k] for k in ("scene", "case", "subject", "fitzpatrick", "image",
                                         "truth", "truth_rps", "projection_floor")}
            base = {**base, "model": name, "projection_floor": case["projection_floor"][name],
                    "fit_dir": str(fit_dir.relative_to(root))}
            if not (fit_dir / "summary.json").is_file():
                reason = reasons.get(case["case"])
                rows.append({**base, "status": "failed" if reason else "missing",
                             "reason": reason or "not fitted (yet): no result folder"})
                continue
            try:
                scores = score_fit(fit_dir, root / case["truth"], loaded[name], colour, regions)
            except (OSError, KeyError, ValueError) as exc:
                rows.append({**base, "status": "failed", "reason": f"scoring: {exc}"})
                continue
            rows.append({**base, "status": "ok", **scores})
    return rows, loaded


def _write_text(path: Path, text: str) -> None:
    from albedo_model.io.atomic import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def run_evaluation(opts: EvaluateOptions, *, log=None) -> dict:
    """Run the evaluation (see the module docstring); return ``results.json``'s content.

    Raises
    ------
    InputError
        Unknown model or scene; ``score_only`` without cases; an ``EVAL`` made
        with other settings.
    """
    from mcmcfit.evaluation.plots import save_accuracy_time, save_calibration
    from mcmcfit.evaluation.report import write_report
    from mcmcfit.evaluation.table import summarise, table_markdown, write_table_csv
    from mcmcfit.outputs.summary import software_versions

    log = log or (lambda text: print(text, file=sys.stderr))
    bad = [m for m in opts.models if m not in MODEL_VARIANTS]
    if bad or not opts.models:
        raise InputError(f"unknown model(s) {', '.join(bad) or '(none)'}; use "
                         f"{', '.join(MODEL_VARIANTS)}")
    root = Path(opts.out)
    t0 = time.perf_counter()
    if opts.score_only:
        cases = load_cases(root)
        if cases is None:
            raise InputError(f"{root}: no cases.json; run `mcmcfit evaluate -o {root}` first")
        missing = [m for m in opts.models if m not in cases["models"]]
        if missing:
            raise InputError(f"{root} has no fits of model(s) {', '.join(missing)}")
        counts = None
    else:
        settings = case_settings(n_subjects=opts.n_subjects, n_held_out=opts.n_held_out,
                                 scenes=opts.scenes, models=opts.models, size=opts.size,
                                 seed=opts.population_seed, detail=opts.detail)
        cases = prepare_cases(root, settings, log=log)
        counts = _fit_models(opts, cases, log)
    rows, loaded = score_all(root, cases, tuple(opts.models))
    summary = summarise(rows)
    labels = {k: v["label"] for k, v in MODEL_VARIANTS.items()}
    table = table_markdown(summary, labels)
    _write_text(root / "table.md", table)
    write_table_csv(summary, root / "table.csv")
    save_calibration(rows, root / "calibration.png")
    save_accuracy_time(rows, root / "accuracy_time.png")
    results = {"format": "mcmcfit-evaluate-1", "settings": cases["settings"],
               "software": software_versions(), "fit_seed": opts.seed,
               "fit_config": (opts.config.to_dict() if opts.config is not None else None),
               "models": {m: cases["models"][m] for m in opts.models},
               "population": cases.get("population"), "batches": counts,
               "table": summary, "rows": rows, "seconds": time.perf_counter() - t0}
    _write_text(root / "results.json", json.dumps(results, indent=1, default=float))
    write_report(root, rows, loaded, table, root / "report.html")
    return results
