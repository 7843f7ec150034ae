"""The notebooks run from top to bottom (with a short schedule) and their numbers make sense."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"


def _execute(path: Path, env: dict[str, str], cwd: Path):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    nb = nbformat.read(path, as_version=4)
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)  # the kernel inherits this process's environment
    try:
        nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                resources={"metadata": {"path": str(cwd)}}).execute()
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return nb


def _text(nb) -> str:
    out = []
    for cell in nb.cells:
        for o in cell.get("outputs", []):
            out.append(o.get("text", "") or o.get("data", {}).get("text/plain", ""))
    return "\n".join(out)


def test_fit_a_face_notebook_runs(default_model_file, tmp_path):
    nb = _execute(NOTEBOOKS / "01_fit_a_face.ipynb",
                  {"MCMCFIT_NOTEBOOK_STEPS": "120", "MCMCFIT_NOTEBOOK_SIZE": "96"}, tmp_path)
    text = _text(nb)
    assert "fit took" in text and "diffuse  RMSE" in text and "R-hat" in text
    assert "summary.json" in text and "report.html" in text
    images = sum(1 for c in nb.cells for o in c.get("outputs", []) if "image/png" in o.get("data", {}))
    assert images >= 3  # target, maps, traces


def _fake_evaluation(root: Path) -> None:
    """An ``EVAL`` folder as ``mcmcfit evaluate`` writes it, from hand-made rows (no fits)."""
    import json

    from mcmcfit.evaluation.plots import save_accuracy_time, save_calibration
    from mcmcfit.evaluation.table import summarise

    rows = []
    for model, mse in (("intrinsic", 0.004), ("baked", 0.012)):
        for i, case in enumerate(("ambient/subject060", "ambient/subject061")):
            rows.append({"scene": "ambient", "case": case, "model": model, "status": "ok",
                         "max_rhat": 1.05, "min_ess_bulk": 80.0, "wall_s": 30.0 + i,
                         "projection_floor": {"diffuse": 8e-4},
                         "diffuse": {"mse": mse * (1 + i), "mse_model_mean": 0.015,
                                     "mse_gain": mse / 2, "width_90": 0.1,
                                     "coverage": {"0.5": 0.4, "0.8": 0.7, "0.9": 0.8,
                                                  "0.95": 0.85}}})
    root.mkdir(parents=True)
    results = {"settings": {"n_subjects": 60, "n_held_out": 2, "scenes": ["ambient"],
                            "size": 80}, "software": {"mcmcfit": "test"}, "fit_seed": 0,
               "models": {"intrinsic": {}, "baked": {}}, "table": summarise(rows), "rows": rows}
    (root / "results.json").write_text(json.dumps(results))
    save_calibration(rows, root / "calibration.png")
    save_accuracy_time(rows, root / "accuracy_time.png")


def test_paper_table1_notebook_reads_results(tmp_path):
    _fake_evaluation(tmp_path / "EVAL")
    nb = _execute(NOTEBOOKS / "03_paper_table1.ipynb", {"MCMCFIT_EVAL": str(tmp_path / "EVAL")},
                  tmp_path)
    text = _text(nb)
    assert "2 held out" in text and "reconstruction table" in text
    assert "0.0060 ± 0.0028" in text  # intrinsic: mean and sd of 0.004 and 0.008
    images = sum(1 for c in nb.cells for o in c.get("outputs", []) if "image/png" in o.get("data", {}))
    assert images == 2  # calibration.png, accuracy_time.png
