"""Hard synthetic cases run to completion with finite outputs (short schedules, default model)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from albedo_model.io.model_files import load_model
from mcmcfit.fitting.fit import fit
from mcmcfit.fitting.mode import ADOPT_GAP
from mcmcfit.outputs.accuracy import albedo_columns
from mcmcfit.fitting.config import FitConfig
from mcmcfit.outputs.posterior import albedo_posterior
from mcmcfit.jobs.synthetic_case import synthetic_case

pytestmark = pytest.mark.embree

HARD_CASES = {
    "yaw 75 deg": dict(seed=21, yaw_deg=75.0),
    "very dark skin": dict(seed=22, skin="dark"),
    "saturated specular highlight": dict(seed=23, highlight=True),
    "24-pixel-wide face": dict(seed=24, face_width_px=24),
    "strong side light": dict(seed=25, side_light=True),
}


@pytest.fixture(scope="module")
def default_model(default_model_file):
    return load_model(default_model_file)


def _finite_params(p) -> bool:
    arrays = [p.pose.translation, (p.pose.yaw, p.pose.pitch, p.pose.roll),
              (p.camera.focal_length, *p.camera.principal_point), p.environment_map.coefficients,
              p.momo.shape, p.momo.albedo, p.momo.expression, p.color_transform.gain,
              p.color_transform.offset, (p.specular_exponent,)]
    return all(np.all(np.isfinite(np.asarray(a, np.float64))) for a in arrays)


@pytest.mark.parametrize("name", list(HARD_CASES))
def test_hard_case_runs_to_completion(default_model, name):
    case = synthetic_case(default_model, **HARD_CASES[name])
    cfg = FitConfig(steps=60, warmup_steps=40, landmark_steps=150, chains=1, thin=5,
                    parallel=False)  # warm-up shortened: only completion is tested
    res = fit(case.image, case.landmarks, default_model, config=cfg, seed=1)
    rec = res.chains[0].stage2
    assert rec.steps == 60 and np.all(np.isfinite(rec.log_posterior))
    assert math.isfinite(res.best.log_lik_img) and math.isfinite(res.best_posterior.log_posterior)
    assert _finite_params(res.best.params) and _finite_params(res.mean_params)
    post = albedo_posterior(default_model.diffuse,
                            res.get_chain(2, flat=True)[:, albedo_columns(res.layout)])
    assert all(np.all(np.isfinite(a)) for a in (post.mean, post.std, post.lo, post.hi))


@pytest.mark.slow
def test_the_first_climb_holds_the_colour_transform(default_model):
    """The demo face of seed 2 (``mcmcfit demo --seed 2``): a far local mode before the fix.

    With the colour transform free in the appearance-only climb, the climb reached contrast
    ~0 (a grey face) under a coloured light: residual RMS 0.096, diffuse RMSE 0.12, the
    noise model measured there flattening the posterior (temperature 174). Held at
    identity until the joint climbs: residual 0.005, RMSE 0.0014 (1-3 min on 2 cores).
    """
    from mcmcfit.outputs.accuracy import albedo_score

    case = synthetic_case(default_model, seed=2, size=250)
    cfg = FitConfig(steps=50, warmup_steps=20, landmark_steps=5000, chains=1, parallel=False)
    res = fit(case.image, case.landmarks, default_model, config=cfg, seed=2)
    assert res.noise["sigma"] < 0.02
    score = albedo_score(default_model, res.get_chain(2, flat=True), res.layout, case.diffuse,
                         case.visible)
    assert score.rmse < 0.01


@pytest.mark.slow
def test_the_approximation_sits_at_the_peak_after_the_warmup(default_model):
    """The same face: in `mcmcfit demo --seed 2` (2 chains) both climbs ended ~240 nats below the
    peak (880 mm from the camera where the truth is 1,175), so the Crank-Nicolson moves about it
    were accepted 1 % of the time and the geometry blocks never (not converged in 10,000 kept
    steps). Whether a climb stops short depends on the chain's path (floating point); whatever
    the path, after the warm-up's re-centring no chain's best draw beats its mode by the gap and
    the moves built on the approximation are accepted (~2 min on 2 cores).
    """
    case = synthetic_case(default_model, seed=2, size=250)
    cfg = FitConfig(steps=250, warmup_steps=250, landmark_steps=5000, chains=2, parallel=True,
                    stop_when_converged=False)
    res = fit(case.image, case.landmarks, default_model, config=cfg, seed=2)
    checks = res.stopping["recentring"]
    assert all(g <= ADOPT_GAP for g in checks[-1]["gains"]), checks
    assert all(m for c in checks[:-1] for m, g in zip(c["moved"], c["gains"]) if g > ADOPT_GAP)
    rates = {k: v.acceptance_rate for k, v in res.acceptance.items()}
    assert rates["pcn"] > 0.1 and rates["gaussian-geometry"] > 0.1, (rates, checks)
