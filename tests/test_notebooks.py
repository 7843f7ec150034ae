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
