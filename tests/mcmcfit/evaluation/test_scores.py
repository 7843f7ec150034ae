"""Scores against hand-computed values; the table's structure from hand-made rows."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from mcmcfit.evaluation.scores import (
    albedo_scores,
    coverage,
    gain_corrected_mse,
    interval_width,
    mse,
    region_mse,
)
from mcmcfit.evaluation.table import COLUMNS, summarise, table_markdown, write_table_csv

TRUTH = np.array([[0.2, 0.4, 0.6], [0.1, 0.1, 0.1], [0.5, 0.5, 0.5]])
EST = np.array([[0.3, 0.4, 0.5], [0.1, 0.3, 0.1], [9.0, 9.0, 9.0]])
ROWS = np.array([True, True, False])


def test_mse_over_visible_rows_only():
    # errors 0.1, 0, -0.1, 0, 0.2, 0 -> squares sum 0.06 over 6 values
    assert mse(EST, TRUTH, ROWS) == pytest.approx(0.01)
    assert mse(TRUTH, TRUTH) == 0.0


def test_gain_corrected_mse_is_least_squares_per_channel():
    truth = np.array([[0.2, 0.4, 0.6], [0.4, 0.2, 0.3]])
    est = truth / np.array([2.0, 4.0, 1.0])          # an exact per-channel scale
    value, gain = gain_corrected_mse(est, truth)
    assert value == pytest.approx(0.0, abs=1e-20)
    np.testing.assert_allclose(gain, [2.0, 4.0, 1.0])
    # one channel, values 1 and 2 against 1 and 1: g = 3/5, residuals 2/5, -1/5 -> MSE 1/10
    v, g = gain_corrected_mse(np.array([[1.0, 1, 1], [2, 1, 1]]), np.array([[1.0, 1, 1], [1, 1, 1]]))
    assert g[0] == pytest.approx(0.6) and g[1] == pytest.approx(1.0)
    assert v == pytest.approx((0.4 ** 2 + 0.2 ** 2) / 6)


def test_coverage_and_width_use_gaussian_intervals():
    mean = np.zeros((4, 3))
    std = np.ones((4, 3))
    # |z| = 0.5, 1.0, 1.5, 2.0 (z_50 = 0.674, z_80 = 1.282, z_90 = 1.645, z_95 = 1.960)
    truth = np.repeat(np.array([[0.5], [1.0], [1.5], [2.0]]), 3, axis=1)
    cov = coverage(mean, std, truth)
    assert cov == {0.5: 0.25, 0.8: 0.5, 0.9: 0.75, 0.95: 0.75}
    assert interval_width(std, None, 0.9) == pytest.approx(2 * 1.6448536, rel=1e-6)


def test_region_mse_and_all_scores():
    regions = {"a": np.array([True, False, True]), "b": np.array([False, False, True])}
    out = region_mse(EST, TRUTH, ROWS, regions)
    assert out == {"a": pytest.approx(0.02 / 3)}      # b has no visible vertex
    s = albedo_scores(EST, np.full((3, 3), 0.1), TRUTH, ROWS, TRUTH, regions=regions)
    assert s["mse"] == pytest.approx(0.01) and s["mse_model_mean"] == 0.0
    assert s["rmse"] == pytest.approx(0.1) and s["n_rows"] == 2
    assert set(s["coverage"]) == {"0.5", "0.8", "0.9", "0.95"}
    # |z| = 1, 0, 1, 0, 2, 0 -> inside the 90 % interval (1.645): 5 of 6
    assert s["coverage"]["0.9"] == pytest.approx(5 / 6)


def _row(scene, model, value, status="ok"):
    return {"scene": scene, "model": model, "status": status, "max_rhat": 1.1,
            "min_ess_bulk": 50.0, "wall_s": 10.0, "projection_floor": {"diffuse": 1e-4},
            "diffuse": {"mse": value, "mse_model_mean": 2 * value, "mse_gain": value / 2,
                        "coverage": {"0.5": 0.5, "0.8": 0.8, "0.9": 0.9, "0.95": 0.95},
                        "width_90": 0.1}, "specular": None}


def test_table_has_one_row_per_scene_and_model(tmp_path):
    rows = [_row("ambient", "intrinsic", 0.004), _row("ambient", "intrinsic", 0.008),
            _row("ambient", "baked", 0.02), _row("ambient", "baked", 0.0, status="failed"),
            _row("directional", "intrinsic", 0.006), _row("directional", "baked", 0.0, "missing")]
    summary = summarise(rows)
    assert [(r["scene"], r["model"], r["n"], r["failed"], r["missing"]) for r in summary] == [
        ("ambient", "intrinsic", 2, 0, 0), ("ambient", "baked", 1, 1, 0),
        ("directional", "intrinsic", 1, 0, 0), ("directional", "baked", 0, 0, 1)]
    first = summary[0]
    assert first["mse_mean"] == pytest.approx(0.006)
    assert first["mse_sd"] == pytest.approx(math.sqrt(2) * 0.002)   # sample sd of 0.004, 0.008
    assert first["mse_model_mean_mean"] == pytest.approx(0.012)
    assert summary[1]["mse_sd"] == 0.0 and math.isnan(summary[1]["spec_mse_mean"])
    md = table_markdown(summary, {"intrinsic": "ours"})
    assert "## scene `ambient`" in md and "## scene `directional`" in md
    assert "| intrinsic (ours) | 0.0060 ± 0.0028 | 0.0120 ± 0.0057 | 2 |" in md
    assert "| 1 (1 failed) |" in md and "| 0 (1 not fitted) |" in md
    assert all(h in md for h in COLUMNS.values())
    write_table_csv(summary, tmp_path / "t.csv")
    with open(tmp_path / "t.csv", newline="") as fh:
        got = list(csv.DictReader(fh))
    assert len(got) == 4 and {"mse_mean", "mse_sd", "cov90_mean", "wall_s_sd"} <= set(got[0])
    assert float(got[0]["mse_mean"]) == pytest.approx(0.006)
