"""Chains in worker processes: the same chains as in this process; warm-up, noise model, stop rule."""

from __future__ import annotations

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from mcmcfit.fitting.chain_pool import ProcessPool, WorkerError
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.fit import fit
from mcmcfit.fitting.initialisation import initial_params
from mcmcfit.fitting.problem import FitProblem
from mcmcfit.sampling.param_vector import ParamLayout


@pytest.fixture(scope="module")
def case():
    model = small_face_model()
    truth = scene(64, 64, yaw=0.25, pitch=-0.1)
    image, clicks = synthetic_target(model, truth)
    return model, image, clicks


def _cfg(**kw) -> FitConfig:
    base = dict(steps=200, landmark_steps=200, warmup_steps=200, adapt_window=50,
                check_every=100, chains=2, thin=5, sigma_lm=2.0, noise_updates=1)
    return FitConfig(**{**base, **kw})


def test_process_chains_are_the_in_process_chains(case):
    model, image, clicks = case
    a = fit(image, clicks, model, config=_cfg(parallel=True), seed=3)
    b = fit(image, clicks, model, config=_cfg(parallel=False), seed=3)
    for ca, cb in zip(a.chains, b.chains):
        for stage in ("stage1", "warmup", "stage2"):
            ra, rb = getattr(ca, stage), getattr(cb, stage)
            assert np.array_equal(ra.samples, rb.samples), stage
            assert np.array_equal(ra.log_lik_img, rb.log_lik_img), stage
    assert a.noise == b.noise and a.stopping["reason"] == b.stopping["reason"]


def test_warmup_is_separate_and_the_noise_model_is_recorded(case):
    model, image, clicks = case
    res = fit(image, clicks, model, config=_cfg(parallel=False), seed=4)
    for c in res.chains:
        assert c.warmup.steps == 200 and c.warmup.stage == "warmup"
        assert c.stage2.steps == 200 and c.stage2.stage == "image"
        assert set(c.warmup.extra["scales"]) >= {"yaw", "shape", "albedo", "light"}
    assert res.noise["source"] == "estimated" and res.noise["sigma"] > 0
    assert res.noise["temperature"] >= 1.0
    assert res.stopping["reason"] in ("converged", "max steps")
    assert [c["kept_steps"] for c in res.stopping["checks"]] == [100, 200][: len(
        res.stopping["checks"])]
    fixed = fit(image, clicks, model, config=_cfg(parallel=False, noise="fixed"), seed=4)
    assert fixed.noise["source"] == "fixed" and fixed.noise["temperature"] == 40.0


def test_a_time_budget_ends_the_kept_draws_early(case):
    model, image, clicks = case
    res = fit(image, clicks, model, config=_cfg(parallel=False, steps=100_000, check_every=50,
                                                 time_budget=1.0), seed=5)
    assert res.stopping["reason"] == "time budget"
    assert 0 < res.stopping["kept_steps"] < 100_000
    assert all(c.stage2.steps == res.stopping["kept_steps"] for c in res.chains)


def test_a_failing_worker_raises_with_its_traceback(case):
    model, image, clicks = case
    cfg = _cfg()
    p0 = initial_params(model, 64, 64, n_shape=cfg.n_shape, n_albedo=cfg.n_albedo,
                        n_expression=cfg.n_expression)
    problem = FitProblem(image, clicks, None, None, model, cfg, p0, ParamLayout.for_params(p0))
    pool = ProcessPool(problem, np.random.SeedSequence(0).spawn(2))
    try:
        with pytest.raises(WorkerError, match="no_such_phase"):
            pool.call("no_such_phase")
    finally:
        pool.close()


def test_widening_splits_the_warmup_and_is_recorded(case):
    """``widen``: at 60 % of the warm-up each chain widens its approximation from pooled draws."""
    model, image, clicks = case
    cfg = _cfg(parallel=False, widen=True, steps=50, warmup_steps=100, check_every=50,
               landmark_steps=100)
    res = fit(image, clicks, model, config=cfg, seed=5)
    found = res.stopping["widening"]
    assert len(found) == 2
    for f in found:
        assert f["n_draws"] > 0 and f["edge"] > 1.0
        assert all(1.0 < r <= 9.0 for r in f["ratios"])
    for c in res.chains:
        assert c.warmup.steps == 100 and c.stage2.steps == 50


def test_fisher_metric_widens_from_warmup_draws_and_their_gradients(case, monkeypatch):
    """``metric="fisher"``: every chain evaluates gradients at its last warm-up draws; all widen."""
    from mcmcfit.fitting import draw_phases

    model, image, clicks = case
    seen = []

    def spy(approx, draws, gradients, **kw):
        seen.append(([d.shape for d in draws], [g.shape for g in gradients]))
        for d, g in zip(draws, gradients):
            assert np.all(np.isfinite(d)) and np.all(np.isfinite(g)) and np.any(g)
        return real(approx, draws, gradients, **kw)

    real = draw_phases.widened_by_fisher
    monkeypatch.setattr(draw_phases, "widened_by_fisher", spy)
    cfg = _cfg(parallel=False, metric="fisher", steps=50, warmup_steps=100, check_every=50,
               landmark_steps=100)
    res = fit(image, clicks, model, config=cfg, seed=5)
    found = res.stopping["widening"]
    assert len(found) == 2 and len(seen) == 2  # each chain widens with all chains' draws
    d = seen[0][0][0][1]
    # half the 60 warm-up steps run, of which every 5th is recorded (thin=5)
    assert seen[0][0] == seen[0][1] == [(12, d), (12, d)]
    for f in found:
        assert f["n_draws"] == 22 and f["edge"] > 1.0 and f["seconds"] > 0
        assert all(1.0 < r <= 9.0 for r in f["ratios"])
    for c in res.chains:
        assert c.warmup.steps == 100 and c.stage2.steps == 50


def test_fisher_metric_survives_gradients_that_fail(case, monkeypatch):
    """A draw whose gradient raises or is not finite is left out; with too few the fit goes on."""
    from mcmcfit.fitting.chain_session import ChainSession

    model, image, clicks = case
    real = ChainSession._coordinate_gradient
    calls = {"n": 0}

    def failing(self):
        grad = real(self)

        def wrapped(params):
            calls["n"] += 1
            if calls["n"] % 2:
                raise ValueError("outside the domain")
            value, g = grad(params)
            return value, np.full_like(np.asarray(g, float), np.nan)
        return wrapped  # only the widening asks for it (no HMC move below)

    monkeypatch.setattr(ChainSession, "_coordinate_gradient", failing)
    cfg = _cfg(parallel=False, metric="fisher", steps=50, warmup_steps=100, check_every=50,
               landmark_steps=100, hmc_weight=0.0)
    res = fit(image, clicks, model, config=cfg, seed=5)
    assert calls["n"] > 0
    assert [f["n_draws"] for f in res.stopping["widening"]] == [0, 0]
    assert all(f["ratios"] == [] for f in res.stopping["widening"])
    for c in res.chains:
        assert c.warmup.steps == 100 and c.stage2.steps == 50


@pytest.mark.parametrize("widens", [False, True])
def test_widening_from_kept_draws_restarts_them_only_when_it_widens(case, monkeypatch, widens):
    """``widen_at``: widened kept draws become warm-up and the kept chain starts again."""
    import mcmcfit.fitting.draw_phases as stage
    from proposals.laplace.widening import Widening

    def fake(approx, draws, **kw):
        assert len(draws) == 2 and kw["effective_fraction"] > 0  # every chain's draws
        ratios = np.array([3.0]) if widens else np.zeros(0)
        return Widening(approx, ratios, np.zeros((approx.size, ratios.size)), 3.0, 2.0,
                        sum(len(d) for d in draws))

    monkeypatch.setattr(stage, "widened_by_draws", fake)
    model, image, clicks = case
    cfg = _cfg(parallel=False, widen_at=50, steps=100, warmup_steps=100, check_every=50,
               landmark_steps=100, stop_when_converged=False)
    res = fit(image, clicks, model, config=cfg, seed=5)
    found = res.stopping["widening_kept"]
    assert found["ratios"] == ([3.0] if widens else [])
    restarted = 50 if widens else 0
    assert found["restarted_after"] == restarted
    for c in res.chains:
        assert c.stage2.steps == 100
        assert c.warmup.steps == 100 + (restarted + 100 if widens else 0)
        # the absorbed draws keep their step indices after the warm-up's
        assert np.all(np.diff(c.warmup.sample_step) > 0)
    assert [ch.get("restarted", False) for ch in res.stopping["checks"]][:1] == [widens]
