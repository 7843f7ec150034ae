"""fit() end to end on a small synthetic image; chain HDF5 round trip; config JSON; light data."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.errors import InputError
from albedo_model.params import Block, ColorTransform, SHLight
from albedo_model.render.renderer import Renderer
from mcmcfit.sampling.chain_file import read_chains_h5
from mcmcfit.targets.face import FaceTarget
from mcmcfit.fitting.fit import fit
from mcmcfit.fitting.config import FitConfig
from mcmcfit.targets.image import ImageLikelihood, linearise, prepare_image_target
from mcmcfit.proposal_data.light import RenderLightData, invert_color_transform
from mcmcfit.targets.priors import LogPrior, PriorConfig
from proposals.base import ProposalState
from proposals.light_solver import solve_sh_light


@pytest.fixture(scope="module")
def small_model():
    return small_face_model()


@pytest.fixture(scope="module")
def small_fit(small_model):
    truth = scene(64, 64, yaw=0.25, pitch=-0.1)
    image, clicks = synthetic_target(small_model, truth)
    cfg = FitConfig(steps=300, landmark_steps=300, chains=2, thin=5, sigma_lm=2.0)
    events = []
    res = fit(image, clicks, small_model, config=cfg, seed=11,
              progress=lambda *e: events.append(e))
    return res, events, truth


def test_fit_result_is_complete_and_consistent(small_fit):
    res, events, truth = small_fit
    assert len(res.chains) == 2
    for c in res.chains:
        # the landmark stage's record is the chosen start's chain (the other starts' short
        # runs, 20 % of the budget in all, are not part of it)
        assert 0.8 * 300 <= c.stage1.steps <= 300 and c.stage2.steps == 300
        assert c.stage2.samples.shape == (60, res.layout.size)
        # the image stage never gets worse than its start in the best sample
        assert c.stage2.best_image.log_lik_img >= c.stage2.log_lik_img[0] - 1e-9 or \
            c.stage2.best_image.step == -1
    assert res.best.log_lik_img == max(c.stage2.best_image.log_lik_img for c in res.chains)
    assert math.isfinite(res.best.log_lik_img) and math.isfinite(res.best_posterior.log_posterior)
    assert sum(s.proposed for s in res.acceptance.values()) == 600
    assert sum(s.proposed for s in res.acceptance_stage1.values()) == sum(
        c.stage1.steps for c in res.chains)
    assert {"stage1_s", "stage2_s", "total_s", "stage2_steps_per_s"} <= set(res.timings)
    assert res.mean_params is not None
    assert res.get_chain(2).shape == (2, 60, res.layout.size)
    assert set(res.diagnostics["stage2"]) >= {"log_posterior", "log_lik_img", "pose.yaw"}
    total = res.config.warmup + 300
    assert ("image", 1, total, total) in events and ("landmarks", 0, 300, 300) in events
    assert abs(res.best.params.pose.yaw - truth.pose.yaw) < 0.1
    json.dumps(res.summary())  # JSON-able


def test_same_seed_same_chain(small_model, small_fit):
    res, _, truth = small_fit
    image, clicks = synthetic_target(small_model, truth)
    again = fit(image, clicks, small_model, config=res.config, seed=11)
    assert np.array_equal(again.chains[0].stage2.samples, res.chains[0].stage2.samples)
    # with the random-walk sampler and a fixed noise model (nothing pooled across
    # chains) a chain does not depend on how many others run beside it (the Gaussian
    # sampler's chains share the pixel region of the best chain's mode by design)
    fixed = res.config.replace(noise="fixed", sampler="random-walk")
    one = fit(image, clicks, small_model, config=fixed.replace(chains=1), seed=11)
    two = fit(image, clicks, small_model, config=fixed, seed=11)
    assert np.array_equal(one.chains[0].stage2.samples, two.chains[0].stage2.samples)


def test_chain_file_round_trip(small_fit, tmp_path):
    res = small_fit[0]
    path = tmp_path / "chain.h5"
    res.save_chain(path)
    chains, layout, attrs = read_chains_h5(path)
    assert layout == res.layout
    assert FitConfig.from_json(attrs["config"]) == res.config
    for a, b in zip(chains, res.chains):
        for ra, rb in ((a.stage1, b.stage1), (a.stage2, b.stage2)):
            for name in ("samples", "sample_step", "log_lik_img", "proposal", "accepted",
                         "rejected_by"):
                assert np.array_equal(getattr(ra, name), getattr(rb, name))
            assert ra.proposal_names == rb.proposal_names
            assert ra.best_image.log_lik_img == rb.best_image.log_lik_img
            assert np.allclose(layout.to_vector(ra.best_image.params),
                               layout.to_vector(rb.best_image.params))


def test_config_json_round_trip_and_validation():
    cfg = FitConfig(steps=5, likelihood="trimmed", prior=PriorConfig(yaw_sigma=0.2), block_size=None)
    assert FitConfig.from_json(cfg.to_json()) == cfg
    for bad in ({"likelihood": "nope"}, {"chains": 0}, {"sigma_px": -1.0}, {"stage1": "x"}):
        with pytest.raises(InputError):
            FitConfig(**bad)
    with pytest.raises(InputError, match="unknown setting"):
        FitConfig.from_dict({"stepz": 3})


@pytest.mark.parametrize("ct", [ColorTransform(),
                                ColorTransform(gain=(1.1, 0.9, 1.05), contrast=0.8,
                                               offset=(0.01, -0.02, 0.0))])
def test_light_data_lets_the_solver_recover_the_light(small_model, ct):
    """Render with a known SH light (no specular); the solver on the data gets it back."""
    light = SHLight.frontal().coefficients + np.array(
        [[0.05, 0.0, -0.05], [0.1, 0.08, 0.05], [0.05, 0.05, 0.05], [-0.1, -0.08, -0.1],
         [0.02, 0.0, 0.0], [0.0, 0.02, 0.0], [0.01, 0.01, 0.01], [0.0, 0.0, 0.02], [0.02, 0.0, 0.0]])
    params = scene(64, 64, yaw=0.2)._replace(environment_map=SHLight(light), color_transform=ct)
    image, _ = synthetic_target(small_model, params)
    renderer = Renderer(small_model, specular=False, threads=1)
    target = FaceTarget(renderer, None, None, LogPrior())
    state = ProposalState(params, target.init_render(params))
    data = RenderLightData(renderer, linearise(image), n_points=300, seed=0)
    normals, albedo, colours = data(state)
    assert normals.shape == (300, 3) and np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    solved = solve_sh_light(normals, albedo, colours, ridge=1e-7)
    assert np.abs(solved - light).max() < 0.02
    assert data(state) is data(state)  # kept while the state's version stamps are
    # a light move keeps them (the data do not read the light); a pose move does not
    lit = params._replace(environment_map=SHLight(light * 0.9))
    assert data(ProposalState(lit, renderer.update(state.render_state, lit, Block.LIGHT))) \
        is data(state)
    turned = params._replace(pose=params.pose._replace(yaw=0.1))
    moved = ProposalState(turned, renderer.update(state.render_state, turned, Block.POSE))
    assert data(moved) is not data(state)
    # stale data are impossible: a render of other parameters, or none, is refused
    with pytest.raises(InputError, match="other parameters"):
        data(ProposalState(turned, state.render_state))
    with pytest.raises(InputError, match="image stage"):
        data(ProposalState(params))


@pytest.mark.parametrize("kind", ["independent", "collective", "trimmed"])
def test_fused_image_likelihood_equals_shade_then_compare(small_model, kind):
    params = scene(64, 64, yaw=0.2)
    image, _ = synthetic_target(small_model, params._replace(
        momo=params.momo._replace(albedo=np.array([0.5, -0.3, 0.2]))))
    renderer = Renderer(small_model, threads=1)
    lik = ImageLikelihood(prepare_image_target(image), kind=kind)
    target = FaceTarget(renderer, lik, None, LogPrior())
    rs = target.init_render(params)
    plain = lik(renderer.shade(rs))
    assert math.isfinite(plain)
    assert target.log_lik_image(rs) == pytest.approx(plain, rel=1e-6, abs=1e-3)


def test_invert_color_transform():
    ct = ColorTransform(gain=(1.2, 0.8, 1.0), contrast=0.7, offset=(0.01, 0.02, -0.03))
    c = np.random.default_rng(0).uniform(0, 1, (5, 3))
    y = 0.3 * c[:, 0] + 0.59 * c[:, 1] + 0.11 * c[:, 2]
    out = np.asarray(ct.gain) * (0.7 * c + 0.3 * y[:, None]) + 2 * np.asarray(ct.offset)
    assert np.allclose(invert_color_transform(out, ct, n_offsets=2), c)
