"""Docstrings of the four packages follow pydocstyle's NumPy convention (ruff's ``D`` rules).

The convention is configured in ``pyproject.toml`` (``[tool.ruff.lint.pydocstyle]``);
this test runs ``ruff check --select D`` on the package sources, as a developer would,
and fails with ruff's report. Skipped when ruff is not installed (it is in the
``test`` extra).
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("albedo_model", "mcmcfit", "pipeline", "proposals")


@pytest.mark.skipif(importlib.util.find_spec("ruff") is None,
                    reason="ruff is not installed (pip install -e '.[test]')")
def test_pydocstyle_numpy_convention():
    cmd = [sys.executable, "-m", "ruff", "check", "--select", "D", "--no-cache", *PACKAGES]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300,
                          check=False)
    report = (proc.stdout + proc.stderr).strip()
    assert proc.returncode == 0, f"ruff {' '.join(cmd[3:])} failed:\n{report}"
