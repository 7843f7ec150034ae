"""The convergence rule (ArviZ rank-normalised split R-hat, bulk/tail ESS) on known series."""

from __future__ import annotations

import numpy as np
import pytest

from mcmcfit.sampling.convergence import ESS_MIN, RHAT_MAX, judge

pytest.importorskip("arviz")


def _ar1(rng, phi: float, chains: int, n: int) -> np.ndarray:
    x = np.zeros((chains, n))
    e = rng.normal(0.0, 1.0, (chains, n))
    for t in range(1, n):
        x[:, t] = phi * x[:, t - 1] + e[:, t]
    return x


@pytest.mark.parametrize("seed", range(3))
def test_independent_draws_converge_and_walks_do_not(seed):
    rng = np.random.default_rng(seed)
    iid = rng.normal(size=(2, 2000))
    assert judge({"x": iid})["converged"]
    walk = np.cumsum(rng.normal(size=(2, 2000)), axis=1)
    verdict = judge({"x": iid, "walk": walk})
    assert not verdict["converged"] and verdict["worst"][0]["name"] == "walk"
    assert verdict["max_rhat"] > RHAT_MAX


@pytest.mark.parametrize("seed", range(3))
def test_one_chain_is_split_and_stuck_chains_fail(seed):
    rng = np.random.default_rng(seed)
    # one chain whose halves differ (a burn-in walk): split R-hat sees it
    drift = np.concatenate([rng.normal(0, 1, 1000), rng.normal(3, 1, 1000)])[None]
    assert not judge({"x": drift})["converged"]
    # two chains stuck in different modes
    modes = np.stack([rng.normal(0, 1, 2000), rng.normal(5, 1, 2000)])
    assert judge({"x": modes})["max_rhat"] > 1.5
    # a slowly mixing but stationary chain: R-hat fine, ESS short of the rule
    slow = _ar1(rng, 0.99, 2, 2000)
    v = judge({"x": slow})
    assert not v["converged"] and v["min_ess_bulk"] < ESS_MIN


def test_nothing_to_judge_is_not_converged():
    assert not judge({})["converged"]
    assert not judge({"x": np.zeros((2, 5))})["converged"]  # too few draws


def test_a_short_fit_says_it_has_not_converged(tmp_path):
    """End to end: summary.json, the report banner and a warning say so."""
    import json
    import warnings

    from face_factory import scene, small_face_model, synthetic_target

    from mcmcfit.fitting.config import FitConfig
    from mcmcfit.jobs.fit_job import FitWarning, LoadedModel, fit_into_folder

    model = small_face_model()
    image, clicks = synthetic_target(model, scene(64, 64, yaw=0.2))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        summary = fit_into_folder(image, clicks, LoadedModel(model), tmp_path / "out",
                                  config=FitConfig(steps=200, warmup_steps=50, landmark_steps=100,
                                                   thin=5))
    assert summary["converged"] is False and summary["convergence"]["n_quantities"] > 10
    assert any(issubclass(w.category, FitWarning) and "NOT converged" in str(w.message)
               for w in caught)
    assert "NOT converged" in (tmp_path / "out" / "report.html").read_text()
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["converged"] is False


# -- monitored_series ---------------------------------------------------------------------


def _record(rng, layout, n_samples=1000, thin=10, phi=0.9, stage="image"):
    from mcmcfit.sampling.chain import BestSample, ChainRecord

    steps = n_samples * thin
    x = _ar1(rng, phi, layout.size, n_samples).T.copy()  # (n, d), every column moves
    x[:, layout.index("pose.scaling")] = 1.0  # never sampled
    best = BestSample(None, -1, 0.0, 0.0, 0.0)
    return ChainRecord(stage, "mh", thin, steps, layout, np.arange(n_samples) * thin + thin - 1, x,
                       rng.normal(size=steps), rng.normal(size=steps), rng.normal(size=steps),
                       np.zeros(steps, np.int32), ("walk",), np.ones(steps, bool),
                       np.zeros(steps, np.int8), best, best, best)


def _regions_basis(rng, layout, n_regions=7):
    from mcmcfit.sampling.derived import RegionAlbedo

    return RegionAlbedo(tuple(f"region{i}" for i in range(n_regions)),
                        rng.uniform(0.2, 0.6, (n_regions, 3)),
                        rng.normal(0, 0.01, (n_regions, layout.n_albedo, 3)))


def test_monitored_series_holds_what_moves_the_log_densities_and_the_regions():
    from mcmcfit.sampling.convergence import LOG_DENSITIES, monitored_series
    from mcmcfit.sampling.derived import region_albedo_means
    from mcmcfit.sampling.param_vector import ParamLayout

    rng = np.random.default_rng(0)
    layout = ParamLayout(4, 5, 6, 2)
    recs = [_record(rng, layout, 200), _record(rng, layout, 180)]
    basis = _regions_basis(rng, layout, 2)
    s = monitored_series(recs, layout, basis, burn_fraction=0.25)
    assert list(s)[:4] == list(LOG_DENSITIES)
    assert "pose.scaling" not in s and "pose.yaw" in s and "albedo.5" in s
    assert s["log_lik_img"].shape == (2, 1800 - 450)  # per step, cut to the shortest
    assert s["pose.yaw"].shape == (2, 180 - 45)  # kept samples
    np.testing.assert_array_equal(s["pose.yaw"][1], recs[1].samples[45:180, 0])
    derived = [k for k in s if k.startswith("albedo_mean.")]
    assert derived == [f"albedo_mean.region{i}.{c}" for i in range(2) for c in "rgb"]
    means = region_albedo_means(recs[0].samples[45:180, layout.slice("albedo")], basis)
    np.testing.assert_allclose(s["albedo_mean.region1.b"][0], means[:, 1, 2])
    landmarks = monitored_series([_record(rng, layout, 50, stage="landmarks")], layout)
    assert "log_lik_img" not in landmarks and "log_posterior" in landmarks
    assert not any(k.startswith("albedo_mean") for k in landmarks)


def test_the_stop_rule_check_is_fast():
    """~140 parameters + 21 region quantities, 2 chains x 1000 draws: a fraction of a second.

    The bound (5 s) only catches a pathological slowdown of a check the fit runs
    every few hundred steps; it is not a speed figure (the tests share the
    machine's cores with each other).
    """
    import time

    from mcmcfit.sampling.convergence import monitored_series
    from mcmcfit.sampling.param_vector import ParamLayout

    rng = np.random.default_rng(1)
    layout = ParamLayout(9, 50, 50, 5)  # 150 columns, 149 move
    recs = [_record(rng, layout, 1000, phi=0.99) for _ in range(2)]
    basis = _regions_basis(rng, layout)
    judge(monitored_series(recs, layout, basis))  # warm-up (imports)
    t0 = time.perf_counter()
    verdict = judge(monitored_series(recs, layout, basis))
    seconds = time.perf_counter() - t0
    assert verdict["n_quantities"] == 4 + 149 + 21 and not verdict["converged"]
    assert seconds < 5.0, seconds
