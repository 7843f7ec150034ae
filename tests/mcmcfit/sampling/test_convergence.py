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
                                  config=FitConfig(steps=200, landmark_steps=100, thin=5))
    assert summary["converged"] is False and summary["convergence"]["n_quantities"] > 10
    assert any(issubclass(w.category, FitWarning) and "NOT converged" in str(w.message)
               for w in caught)
    assert "NOT converged" in (tmp_path / "out" / "report.html").read_text()
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["converged"] is False
