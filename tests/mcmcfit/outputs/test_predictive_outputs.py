"""Predictive intervals in the outputs: scores, posterior.npz, summary fields, report, demo lines."""

from pathlib import Path

import numpy as np
import pytest

from albedo_model.pca import PCAPart
from mcmcfit.commands.demo import format_demo_result
from mcmcfit.outputs.accuracy import posterior_interval_error
from mcmcfit.outputs.albedo_summary import (
    PosteriorAlbedo,
    albedo_interval_fields,
    write_posterior_npz,
)
from mcmcfit.outputs.posterior import albedo_posterior
from mcmcfit.outputs.report import render_report
from mcmcfit.outputs.vertex_maps import std_maps


def _post(residual: bool, seed: int = 0, n: int = 200):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((3 * n, 4)))
    r = np.full(3 * n, 1e-4) if residual else None
    part = PCAPart(rng.uniform(0.2, 0.5, 3 * n), q, np.full(4, 0.02), residual_variance=r)
    c_true = rng.standard_normal(4)
    samples = c_true + 0.05 * rng.standard_normal((300, 4))
    truth = part.instance(c_true) + 0.01 * rng.standard_normal(3 * n)
    return albedo_posterior(part, samples), truth.reshape(-1, 3)


def test_both_coverages_are_scored():
    post, truth = _post(True)
    visible = np.ones(len(truth), bool)
    e = posterior_interval_error(post, truth, visible)
    assert e["predictive"] and e["coverage"] == e["coverage_predictive"]
    assert e["coverage_predictive"] > 0.8 > e["coverage_coefficients"]
    plain, truth = _post(False)
    e = posterior_interval_error(plain, truth, visible)
    assert not e["predictive"] and e["coverage_predictive"] is None
    assert e["coverage"] == e["coverage_coefficients"]


def test_npz_summary_fields_and_maps(tmp_path):
    post, _ = _post(True)
    visible = np.zeros(len(post.mean), bool)
    visible[:50] = True
    pa = PosteriorAlbedo(post, None, visible, 300)
    write_posterior_npz(tmp_path / "p.npz", pa)
    with np.load(tmp_path / "p.npz") as z:
        assert bool(z["diffuse_predictive"])
        np.testing.assert_array_equal(z["diffuse_coef_std"], post.coef_std)
        np.testing.assert_array_equal(z["diffuse_std"], post.std)
        np.testing.assert_allclose(z["diffuse_residual_std"], 0.01, rtol=1e-5)
    fields = albedo_interval_fields(pa)
    assert fields["predictive"] and "predictive" in fields["interval_kind"]
    assert fields["residual_variance"]["diffuse"] == {
        "present": True, "rms_rgb": pytest.approx([0.01] * 3, rel=1e-5)}
    assert (fields["diffuse_std_predictive_visible_mean"]
            > fields["diffuse_std_coefficients_visible_mean"])
    labels = [label for label, _ in std_maps(post)]
    assert labels == ["coefficients only", "predictive (+ out-of-span variance)"]
    plain, _ = _post(False)
    pa = PosteriorAlbedo(plain, None, visible, 300)
    fields = albedo_interval_fields(pa)
    assert not fields["predictive"] and fields["residual_variance"]["diffuse"]["present"] is False
    assert fields["diffuse_std_predictive_visible_mean"] is None
    assert [label for label, _ in std_maps(plain)] == ["coefficients only"]
    write_posterior_npz(tmp_path / "q.npz", pa)
    with np.load(tmp_path / "q.npz") as z:
        assert not bool(z["diffuse_predictive"]) and "diffuse_residual_std" not in z


def _summary(predictive: bool) -> dict:
    e = {"rmse": 0.0135, "mean_abs": 0.01, "coverage": 0.97 if predictive else 0.88,
         "coverage_coefficients": 0.88, "coverage_predictive": 0.97 if predictive else None,
         "predictive": predictive}
    albedo = {"predictive": predictive,
              "residual_variance": {"diffuse": {"present": predictive,
                                                "rms_rgb": [0.013, 0.0097, 0.0084]
                                                if predictive else None}}}
    return {"truth": {"interval": 0.9, "n_visible": 1000, "diffuse": e},
            "albedo": albedo, "timings": {"total_s": 1.0, "stage1_s": 0.5, "stage2_s": 0.5}}


def test_report_shows_both_kinds():
    text = render_report(_summary(True), files=set())
    assert "90 % predictive" in text and "90 % coefficients only" in text
    assert "0.97" in text and "0.88" in text and "leave-one-out" in text
    text = render_report(_summary(False), files=set())
    assert "no residual variance" in text
    # an older summary without the split keeps its single column
    old = _summary(True)
    old["truth"]["diffuse"] = {"rmse": 0.01, "mean_abs": 0.01, "coverage": 0.9}
    del old["albedo"]
    assert "coverage" in render_report(old, files=set())


def test_demo_lines_name_the_coverage():
    text = format_demo_result(Path("/x"), _summary(True))
    assert ("coverage of the 90 % intervals: predictive 97.0 %, coefficients only 88.0 %"
            in text)
    text = format_demo_result(Path("/x"), _summary(False))
    assert "coefficients only 88.0 % (the model has no residual variance)" in text
    old = _summary(True)
    old["truth"]["diffuse"] = {"rmse": 0.01, "mean_abs": 0.01, "coverage": 0.9}
    assert "coverage of the 90 % intervals: 90.0 %" in format_demo_result(Path("/x"), old)


def test_albedo_score_scores_the_visible_rows_with_both_coverages():
    import dataclasses

    from momo_factory import synthetic_model

    from mcmcfit.outputs.accuracy import albedo_score
    from mcmcfit.sampling.param_vector import ParamLayout

    model = synthetic_model(0)
    d = model.diffuse
    model = dataclasses.replace(model, diffuse=d.with_residual_variance(np.full(d.dim, 1e-2)))
    layout = ParamLayout(4, model.shape.rank, d.rank, model.expression.rank)
    rng = np.random.default_rng(0)
    samples = rng.normal(0.0, 0.1, (400, len(layout.names)))
    truth = (model.diffuse_instance(np.full(d.rank, 0.05))
             + 0.1 * rng.standard_normal((model.n_vertices, 3)))
    visible = np.arange(model.n_vertices) % 3 != 0
    score = albedo_score(model, samples, layout, truth, visible)
    post = albedo_posterior(model.diffuse, samples[:, layout.slice("albedo")])
    ref = posterior_interval_error(post, truth, visible)
    assert score.predictive and score.n_samples == 400
    assert score.rmse == pytest.approx(ref["rmse"], rel=1e-6)
    assert score.coverage_coefficients == pytest.approx(ref["coverage_coefficients"])
    # Monte Carlo bounds of different row blocks: close, not identical
    assert abs(score.coverage - ref["coverage"]) < 0.1 and score.coverage > 0.8
