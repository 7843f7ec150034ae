"""The evaluation's table: mean +- sd per model and scene, in the paper's Table 1 form.

:func:`summarise` groups the scored rows (one per case and model) by scene
and model and takes the mean and sample sd of each score; :func:`table_markdown`
writes the paper's Table 1 (reconstruction MSE and model-mean MSE per model)
for each scene, then the full table (gain-corrected MSE, projection floor,
coverage at the nominal levels, interval width, specular MSE, R-hat, ESS,
wall time); :func:`write_table_csv` writes one CSV row per scene and model
with a ``_mean`` and ``_sd`` column per score.

This module imports numpy and the standard library only.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

__all__ = ["COLUMNS", "row_values", "summarise", "table_markdown", "write_table_csv"]

#: Scores aggregated per scene and model: key -> header.
COLUMNS = {
    "mse": "MSE (posterior mean)", "mse_model_mean": "MSE (model mean)",
    "mse_gain": "MSE after RGB gain", "floor": "projection floor",
    "cov50": "cov. 50 %", "cov80": "cov. 80 %", "cov90": "cov. 90 %", "cov95": "cov. 95 %",
    "width90": "90 % width", "spec_mse": "specular MSE", "max_rhat": "max R-hat",
    "min_ess_bulk": "min bulk-ESS", "wall_s": "wall time (s)",
}


def row_values(row: dict) -> dict[str, float]:
    """Return the :data:`COLUMNS` values of one scored row (NaN where absent)."""
    d = row.get("diffuse") or {}
    s = row.get("specular") or {}
    cov = d.get("coverage") or {}
    floor = ((row.get("projection_floor") or {}).get("diffuse"))
    raw = {"mse": d.get("mse"), "mse_model_mean": d.get("mse_model_mean"),
           "mse_gain": d.get("mse_gain"), "floor": floor,
           "cov50": cov.get("0.5"), "cov80": cov.get("0.8"), "cov90": cov.get("0.9"),
           "cov95": cov.get("0.95"), "width90": d.get("width_90"), "spec_mse": s.get("mse"),
           "max_rhat": row.get("max_rhat"), "min_ess_bulk": row.get("min_ess_bulk"),
           "wall_s": row.get("wall_s")}
    return {k: math.nan if v is None else float(v) for k, v in raw.items()}


def summarise(rows: list[dict]) -> list[dict]:
    """Group the ``"ok"`` rows by (scene, model): n and mean/sd of every column.

    Returns
    -------
    list of dict
        ``scene``, ``model``, ``n``, ``failed``, ``missing`` (not fitted yet) and
        ``<key>_mean``, ``<key>_sd``
        for each key of :data:`COLUMNS`, in the order scenes and models first appear.
    """
    groups: dict[tuple, list] = {}
    failed: dict[tuple, int] = {}
    missing: dict[tuple, int] = {}
    for r in rows:
        key = (r["scene"], r["model"])
        groups.setdefault(key, [])
        if r.get("status") == "ok":
            groups[key].append(row_values(r))
        elif r.get("status") == "missing":
            missing[key] = missing.get(key, 0) + 1
        else:
            failed[key] = failed.get(key, 0) + 1
    out = []
    for (scene, model), vals in groups.items():
        rec = {"scene": scene, "model": model, "n": len(vals),
               "failed": failed.get((scene, model), 0), "missing": missing.get((scene, model), 0)}
        for k in COLUMNS:
            x = np.array([v[k] for v in vals], float)
            x = x[np.isfinite(x)]
            rec[f"{k}_mean"] = float(x.mean()) if x.size else math.nan
            rec[f"{k}_sd"] = float(x.std(ddof=1)) if x.size > 1 else (0.0 if x.size else math.nan)
        out.append(rec)
    return out


def _fmt(mean: float, sd: float, key: str) -> str:
    if not math.isfinite(mean):
        return "-"
    if key.startswith("cov"):
        return f"{100 * mean:.1f} ± {100 * sd:.1f} %"
    if key in ("max_rhat",):
        return f"{mean:.2f} ± {sd:.2f}"
    if key in ("min_ess_bulk", "wall_s"):
        return f"{mean:.0f} ± {sd:.0f}"
    return f"{mean:.4f} ± {sd:.4f}" if mean >= 1e-3 else f"{mean:.2e} ± {sd:.1e}"


def table_markdown(summary: list[dict], labels: dict[str, str] | None = None) -> str:
    """Return ``table.md``: Table 1 per scene, then the full table."""
    labels = labels or {}
    lines = ["# Held-out albedo reconstruction (the paper's Table 1)", "",
             "Mean ± sd over the held-out cases; MSE of linear sRGB albedo on the vertices "
             "visible in the true view.", ""]
    for scene in dict.fromkeys(r["scene"] for r in summary):
        lines += [f"## scene `{scene}`", "", "| model | reconstruction | model mean | n |",
                  "|---|---|---|---|"]
        for r in (r for r in summary if r["scene"] == scene):
            name = r["model"] + (f" ({labels[r['model']]})" if r["model"] in labels else "")
            failed = "".join(f" ({r[k]} {k if k == 'failed' else 'not fitted'})"
                             for k in ("failed", "missing") if r.get(k))
            lines.append(f"| {name} | {_fmt(r['mse_mean'], r['mse_sd'], 'mse')} | "
                         f"{_fmt(r['mse_model_mean_mean'], r['mse_model_mean_sd'], 'mse')} | "
                         f"{r['n']}{failed} |")
        lines.append("")
    lines += ["## all scores", "",
              "| scene | model | n | " + " | ".join(COLUMNS.values()) + " |",
              "|---|---|---|" + "---|" * len(COLUMNS)]
    for r in summary:
        cells = [_fmt(r[f"{k}_mean"], r[f"{k}_sd"], k) for k in COLUMNS]
        lines.append(f"| {r['scene']} | {r['model']} | {r['n']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_table_csv(summary: list[dict], path: Path) -> None:
    """Write one row per scene and model: ``scene, model, n, failed, missing, <key>_mean, ...``."""
    fields = ["scene", "model", "n", "failed", "missing"] + [f"{k}_{s}" for k in COLUMNS
                                                  for s in ("mean", "sd")]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        for r in summary:
            w.writerow({k: r[k] for k in fields})
