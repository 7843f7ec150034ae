"""The rows of a batch report: one per image, from the journals of OUT.

The current state of an image is its last ``batch.jsonl`` line when it has a
complete result folder (a re-fit with ``--force`` replaces the earlier line),
otherwise its last ``failures.jsonl`` line (failed or skipped). Images fitted
in an earlier run and failing in a later ``--force`` run keep their result
(the failed fit never replaced the folder). The subject of an image is the
first component of its relative path (LFW: ``Name/Name_0001``), or ``"."`` for
an image at the top of INPUT; under ``batch --group-by person`` a row is a
person (its relative path, ``n_images`` photographs fitted together).

This module imports :mod:`mcmcfit.batch` modules, the standard library and, when
it writes the CSV, :mod:`albedo_model.io.atomic`.
"""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path, PurePosixPath

from mcmcfit.batch.journal import BATCH_JOURNAL, FAILURES_JOURNAL, read_journal
from mcmcfit.batch.out_paths import is_complete, result_dir

__all__ = ["CSV_COLUMNS", "batch_rows", "subject_of", "write_csv"]

#: Columns of the CSV export, in order.
CSV_COLUMNS = ("subject", "path", "relative", "status", "seconds", "fit_seconds", "acceptance",
               "acceptance_stage1", "landmark_rms_px", "diffuse_r", "diffuse_g", "diffuse_b",
               "diffuse_mean", "diffuse_std_mean", "specular_mean", "seed", "error_type",
               "reason", "finished_at", "n_images")


def subject_of(relative: str) -> str:
    """Return the top-level folder of a relative path (the LFW subject), ``"."`` at the top."""
    parts = PurePosixPath(relative).parts
    return parts[0] if len(parts) > 1 else "."


def _num(x) -> float | None:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) \
        and math.isfinite(x) else None


def _ok_row(r: dict) -> dict:
    alb = r.get("albedo") or {}
    rgb = alb.get("diffuse_mean_rgb") or [None, None, None]
    return {"status": "ok", "seconds": _num(r.get("seconds")),
            "fit_seconds": _num(r.get("fit_seconds")), "acceptance": _num(r.get("acceptance")),
            "acceptance_stage1": _num(r.get("acceptance_stage1")),
            "landmark_rms_px": _num(r.get("landmark_rms_px")),
            "diffuse_r": _num(rgb[0]), "diffuse_g": _num(rgb[1]), "diffuse_b": _num(rgb[2]),
            "diffuse_mean": _num(alb.get("diffuse_mean")),
            "diffuse_std_mean": _num(alb.get("diffuse_std_mean")),
            "specular_mean": _num(alb.get("specular_mean")), "error_type": "", "reason": "",
            "n_images": r.get("n_images") or len(r.get("images") or []) or 1}


def batch_rows(out: str | os.PathLike) -> list[dict]:
    """One dict per image of the batch folder ``out`` (keys: :data:`CSV_COLUMNS`), sorted by path.

    Images with a complete result folder are "ok"; the others take the status
    of their last failure line ("failed" or "skipped").
    """
    out = Path(out)
    rows: dict[str, dict] = {}
    for r in read_journal(out / BATCH_JOURNAL):
        rel = r.get("relative")
        if r.get("status") != "ok" or not rel:
            continue
        try:
            complete = is_complete(result_dir(out, PurePosixPath(rel)))
        except ValueError:
            continue
        if complete:
            rows[rel] = {"path": r.get("path", rel), "relative": rel, "seed": r.get("seed"),
                         "finished_at": r.get("finished_at", ""),
                         "person": "images" in r or (r.get("n_images") or 1) > 1,
                         **_ok_row(r)}
    for r in read_journal(out / FAILURES_JOURNAL):
        key = r.get("relative") or r.get("path") or ""
        if not key or key in rows and rows[key]["status"] == "ok":
            continue
        rows[key] = {"path": r.get("path", key), "relative": r.get("relative") or "",
                     "status": r.get("status", "failed"), "seconds": _num(r.get("seconds")),
                     "seed": r.get("seed"), "error_type": r.get("error_type", ""),
                     "reason": r.get("reason", ""), "finished_at": r.get("finished_at", ""),
                     "person": "images" in r}
    table = []
    for key in sorted(rows):
        row = {c: None for c in CSV_COLUMNS}
        row.update(rows[key])
        where = row["relative"] or row["path"]
        row["subject"] = where if row.pop("person", False) else subject_of(where)
        table.append(row)
    return table


def write_csv(rows: list[dict], path: str | os.PathLike) -> None:
    """Write the rows as CSV (:data:`CSV_COLUMNS`; empty cells for missing values), atomically."""
    from albedo_model.io.atomic import atomic_path

    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(CSV_COLUMNS), extrasaction="ignore")
        w.writeheader()
        for row in rows:
            w.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in CSV_COLUMNS})
