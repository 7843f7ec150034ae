"""Joint states of several images: lifted moves, the shared albedo conditional, stationarity."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from mh_chain import DropRatio, assert_moments, base_state, moment_errors, random_state, run_chain

from albedo_model.errors import InputError
from albedo_model.params import Block, SHLight
from proposals.albedo_solver import AlbedoConditional, albedo_system
from proposals.base import ProposalState, mixture
from proposals.coefficients import CoefficientWalk
from proposals.joint import ForImage, JointParameter, SharedAlbedoConditional
from proposals.light import SHIntensity

SIGMA = 0.05
N = 12_000


def _joint(n=2, seed=0):
    rng = np.random.default_rng(seed)
    return JointParameter.share([random_state(rng, n_albedo=6) for _ in range(n)])


def test_share_gives_every_image_one_identity():
    jp = _joint(3)
    first = jp.images[0].momo
    for p in jp.images:
        assert p.momo.shape is first.shape and p.momo.albedo is first.albedo
    assert jp.images[1].pose != jp.images[0].pose  # the scenes stay each image's own
    with pytest.raises(InputError, match="at least one image"):
        JointParameter.share([])


def test_a_lifted_move_of_a_shared_block_reaches_every_image():
    jp = _joint()
    move = ForImage(1, CoefficientWalk(Block.ALBEDO, 0.1))(np.random.default_rng(1),
                                                            ProposalState(jp))
    assert move.name.endswith("@1") and move.touched == Block.ALBEDO
    a, b = move.params.images
    assert a.momo.albedo is b.momo.albedo
    assert not np.array_equal(a.momo.albedo, jp.images[0].momo.albedo)
    assert a.pose is jp.images[0].pose and a.environment_map is jp.images[0].environment_map


def test_a_lifted_move_of_an_own_block_leaves_the_other_images_alone():
    jp = _joint()
    move = ForImage(0, SHIntensity(0.1))(np.random.default_rng(2), ProposalState(jp))
    assert move.touched == Block.LIGHT
    assert move.params.images[1] is jp.images[1]
    s = move.params.images[0].environment_map.coefficients / jp.images[0].environment_map.coefficients
    assert move.log_q_ratio == pytest.approx(27 * np.log(s[0, 0]), rel=1e-12)


def _light_target(jp):
    return -0.5 * sum(float(np.sum(p.environment_map.coefficients ** 2)) for p in jp.images)


def test_lifted_moves_sample_each_images_own_block():
    """Two images' lights, each N(0, I): the squared radius of each is chi-square(27)."""
    start = JointParameter.share([base_state()._replace(environment_map=SHLight(
        np.random.default_rng(k).normal(size=(9, 3)))) for k in range(2)])
    feat = lambda jp: [float(np.sum(p.environment_map.coefficients ** 2)) for p in jp.images]  # noqa: E731
    prop = mixture((1.0, ForImage(0, SHIntensity(0.25))), (1.0, ForImage(1, SHIntensity(0.25))))
    samples, _ = run_chain(prop, _light_target, start, feat, 2 * N, seed=3)
    assert_moments(samples, 27, np.sqrt(54))
    wrong = mixture((1.0, DropRatio(ForImage(0, SHIntensity(0.25)))),
                    (1.0, DropRatio(ForImage(1, SHIntensity(0.25)))))
    bad, _ = run_chain(wrong, _light_target, start, feat, N, seed=3)
    assert moment_errors(bad, 27, np.sqrt(54)).max() > 0.15


def _system(rng, c_true, n=300, k=6, scale=1.0):
    jac = rng.normal(0, 0.1, (n, 3, k)).astype(np.float32) * scale
    mean = rng.uniform(0.1, 0.3, (n, 3)).astype(np.float32)
    off = np.array([0.01, -0.02, 0.0], np.float32)
    target = (mean + np.einsum("ncj,j->nc", jac, c_true) + off
              + rng.normal(0, SIGMA, (n, 3))).astype(np.float32)
    return albedo_system(jac, mean, np.full((n, 3), 0.2, np.float32), target, off,
                         np.arange(n), 10**6, key=("fixed",))


def _systems(n_images=2, seed=0, k=6):
    rng = np.random.default_rng(seed)
    c_true = rng.normal(0, 1, k)
    # the second image sees the albedo weaker (a darker light): unequal information
    return [_system(rng, c_true, k=k, scale=1.0 if i == 0 else 0.4) for i in range(n_images)]


def _state(jp):
    return SimpleNamespace(params=jp, render_state=SimpleNamespace(states=(None,) * jp.n_images))


def _with_albedo(jp, c):
    first = jp.images[0]
    return jp.with_image(0, first._replace(momo=first.momo._replace(albedo=np.asarray(c))),
                         Block.ALBEDO)


def _exact_posterior(systems, sigmas):
    k = systems[0].jac.shape[2]
    lam, h = np.eye(k), np.zeros(k)
    for s, sigma in zip(systems, sigmas):
        j = s.jac.reshape(-1, k).astype(np.float64)
        y = (s.target - s.mean - s.off).reshape(-1).astype(np.float64)
        lam += j.T @ j / sigma**2
        h += j.T @ y / sigma**2
    return np.linalg.solve(lam, h), lam


def _log_target(systems, sigmas):
    def log_p(jp):
        c = np.asarray(jp.images[0].momo.albedo, np.float64)
        out = -0.5 * float(c @ c)
        for s, sigma in zip(systems, sigmas):
            r = s.target - (s.mean + np.einsum("ncj,j->nc", s.jac, c) + s.off)
            out -= 0.5 * float(np.sum(r.astype(np.float64) ** 2)) / sigma**2
        return out
    return log_p


def test_shared_conditional_is_the_stacked_least_squares_posterior():
    systems = _systems()
    sigmas = [SIGMA, 2 * SIGMA]
    prop = SharedAlbedoConditional([lambda s, x=x: x for x in systems], sigmas)
    jp = _joint()
    mean, chol = prop.conditional(_state(jp))
    expect_mean, lam = _exact_posterior(systems, sigmas)
    np.testing.assert_allclose(mean, expect_mean, atol=1e-4)
    np.testing.assert_allclose(chol @ chol.T, lam, atol=1e-5 * np.abs(lam).max())


def test_for_one_image_it_is_the_single_image_conditional():
    (system,) = _systems(1)
    jp = _joint(1)
    one = SharedAlbedoConditional([lambda s: system], [SIGMA])(np.random.default_rng(4), _state(jp))
    single = AlbedoConditional(lambda s: system, sigma=SIGMA)(np.random.default_rng(4),
                                                              ProposalState(jp.images[0]))
    assert np.array_equal(one.params.images[0].momo.albedo, single.params.momo.albedo)
    assert one.log_q_ratio == single.log_q_ratio and one.joint and single.joint


def test_shared_conditional_is_a_gibbs_draw_on_a_linear_model():
    systems = _systems(3, seed=5)
    sigmas = [SIGMA, SIGMA, 1.5 * SIGMA]
    log_p = _log_target(systems, sigmas)
    prop = SharedAlbedoConditional([lambda s, x=x: x for x in systems], sigmas)
    jp = _joint(3)
    rng = np.random.default_rng(6)
    for _ in range(5):
        move = prop(rng, _state(jp))
        assert move.touched == Block.ALBEDO
        shared = {id(p.momo.albedo) for p in move.params.images}
        assert len(shared) == 1
        # float32 normal equations: exact up to ~1e-2 on terms of size ~1e1..1e3
        assert log_p(move.params) - log_p(jp) + move.log_q_ratio == pytest.approx(0.0, abs=0.05)
        jp = move.params


def test_shared_conditional_samples_the_joint_posterior_and_one_image_alone_does_not():
    systems = _systems(2, seed=7, k=3)
    sigmas = [SIGMA, SIGMA]
    mean, lam = _exact_posterior(systems, sigmas)
    sd = np.sqrt(np.diag(np.linalg.inv(lam)))
    log_p = _log_target(systems, sigmas)
    start = _with_albedo(_joint(2, seed=1), np.zeros(3))
    feat = lambda jp: np.asarray(jp.images[0].momo.albedo)  # noqa: E731
    joint = SharedAlbedoConditional([lambda s, x=x: x for x in systems], sigmas)
    # a small random walk beside it, so that successive draws are not independent by design
    walk = ForImage(1, CoefficientWalk(Block.ALBEDO, 0.02))
    samples, _ = run_chain(mixture((1.0, joint), (1.0, walk)), log_p, start, feat, 6000, seed=8)
    assert_moments(samples, mean, sd, burn=200)
    # negative control: the first image's conditional alone with its ratio dropped samples
    # that image's posterior (the second image's information is lost: sd ~28 % too wide)
    alone = DropRatio(SharedAlbedoConditional([lambda s: systems[0]], [SIGMA]))
    bad, _ = run_chain(alone, log_p, JointParameter((start.images[0],)), feat, 3000, seed=8)
    assert moment_errors(bad, mean, sd, burn=200).max() > 0.15


def test_bad_arguments_are_refused():
    with pytest.raises(InputError, match="one albedo data source and one sigma"):
        SharedAlbedoConditional([lambda s: None], [SIGMA, SIGMA])
    with pytest.raises(InputError, match="must be finite and > 0"):
        SharedAlbedoConditional([lambda s: None], [0.0])
    jp = _joint()
    none = SharedAlbedoConditional([lambda s: None, lambda s: None], [SIGMA, SIGMA])
    assert none(np.random.default_rng(0), _state(jp)).touched == Block.NONE


def test_lift_keeps_the_schedule_leaf_by_leaf():
    from proposals.base import leaves
    from proposals.joint import lift

    walks = mixture((1.0, CoefficientWalk(Block.ALBEDO, 0.1)), (3.0, SHIntensity(0.1)),
                    name="inner")
    lifted = lift(1, mixture((1.0, walks), (1.0, SHIntensity(0.2)), name="outer"))
    got = [(round(p, 6), leaf.name, leaf.touches) for p, leaf in leaves(lifted)]
    want = [(round(p, 6), f"{leaf.name}@1", leaf.touches)
            for p, leaf in leaves(mixture((1.0, walks), (1.0, SHIntensity(0.2))))]
    assert got == want
    jp = _joint()
    move = lifted(np.random.default_rng(0), ProposalState(jp))
    assert move.name.endswith("@1") and move.params.images[0] is jp.images[0] or (
        move.touched & Block.ALBEDO)
