"""notebooks/02_batch_lfw.ipynb runs from top to bottom on a tiny batch and reads its results."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "02_batch_lfw.ipynb"


def test_batch_notebook_runs(default_model_file, tmp_path, monkeypatch):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    # the kernel and the batch it starts inherit this environment (MCMCFIT_CACHE is set
    # by default_model_file, so "default" is the session's model)
    for key, value in {"MCMCFIT_NOTEBOOK_STEPS": "40", "MCMCFIT_NOTEBOOK_SIZE": "80",
                       "MCMCFIT_NOTEBOOK_IMAGES": "2", "MCMCFIT_NOTEBOOK_WORKERS": "2"}.items():
        monkeypatch.setenv(key, value)
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}}).execute()
    text = "\n".join(o.get("text", "") or o.get("data", {}).get("text/plain", "")
                     for c in nb.cells for o in c.get("outputs", []))
    out = tmp_path / "batch_lfw_demo" / "OUT"
    # first run: 2 fitted, the corrupt image failed, the one without landmarks skipped
    assert "2 fitted, 1 failed, 0 already complete, 1 skipped" in text
    # second run with --face-box-default: only the image without landmarks is new
    assert "1 fitted, 1 failed, 2 already complete, 0 skipped" in text
    assert "exit code 1" in text
    assert "not a readable image" in text
    assert len(list(out.rglob("summary.json"))) == 3
    assert (out / "summary.html").is_file() and (out / "summary.csv").is_file()
    images = sum(1 for c in nb.cells for o in c.get("outputs", [])
                 if "image/png" in o.get("data", {}))
    assert images >= 4  # the tree, albedo vs truth, two report plots
    assert os.environ.get("MCMCFIT_CACHE")  # the fixture's cache was the one used
