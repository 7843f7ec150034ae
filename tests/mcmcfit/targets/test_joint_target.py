"""The joint target of several renders of one face: densities, caches, what each move renders."""

from __future__ import annotations

import math

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.errors import InputError
from albedo_model.params import Block, MoMoCoefficients, SHLight
from albedo_model.render.renderer import Renderer
from mcmcfit.proposal_data.albedo import RenderAlbedoData
from mcmcfit.sampling.kernel import init, run
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.image import ImageLikelihood, linearise, prepare_image_target
from mcmcfit.targets.joint import JointTarget
from mcmcfit.targets.priors import LogPrior
from proposals.base import mixture
from proposals.coefficients import CoefficientWalk
from proposals.joint import ForImage, JointParameter, SharedAlbedoConditional
from proposals.light import SHIntensity
from proposals.pose import Rotation

SIGMA = 0.043
TRUTH = MoMoCoefficients(np.array([1.0, -0.5, 0.3, 0.2]), np.array([0.8, -0.6, 0.4]),
                         np.array([0.3, -0.2]))


@pytest.fixture(scope="module")
def model():
    return small_face_model(specular=False)


@pytest.fixture(scope="module")
def scenes(model):
    truths = [scene(64, 64, yaw=y, coefficients=TRUTH)._replace(
        environment_map=SHLight.frontal(0.6 + 0.15 * k, 0.3)) for k, y in enumerate((-0.35, 0.3))]
    return truths, [synthetic_target(model, t)[0] for t in truths]


def _face(model, image):
    renderer = Renderer(model, specular=False, threads=1)
    target = prepare_image_target(image, bins=25, smooth_sigma=SIGMA)
    lik = ImageLikelihood(target, kind="independent", sigma=SIGMA, temperature=1.0,
                          background=renderer.background)
    return FaceTarget(renderer, lik, None, LogPrior())


def _target(model, images):
    return JointTarget([_face(model, im) for im in images], LogPrior())


def _start(truths):
    # the identity starts at the model mean; each scene at its truth
    return JointParameter.share([t._replace(momo=t.momo._replace(
        shape=np.zeros(4), albedo=np.zeros(3))) for t in truths])


def test_one_image_is_its_face_target(model, scenes):
    truths, images = scenes
    face = _face(model, images[0])
    joint = init(JointParameter((truths[0],)), JointTarget([face], LogPrior()))
    single = init(truths[0], _face(model, images[0]))
    assert (joint.log_prior, joint.log_lik_lm, joint.log_lik_img) == (
        single.log_prior, single.log_lik_lm, single.log_lik_img)


def test_the_identity_prior_is_counted_once(model, scenes):
    truths, images = scenes
    target = _target(model, images)
    jp = JointParameter.share(truths)
    prior = LogPrior()
    once = prior.terms(truths[0])
    expect = sum(prior(p) for p in jp.images) - (len(truths) - 1) * (once["shape"] + once["albedo"])
    assert target.log_prior(jp) == pytest.approx(expect, rel=1e-12)
    with pytest.raises(InputError, match="1 images, the target 2"):
        target.log_prior(JointParameter((truths[0],)))


def test_a_move_renders_only_the_images_it_changed(model, scenes):
    truths, images = scenes
    target = _target(model, images)
    state = init(_start(truths), target)
    rng = np.random.default_rng(0)
    own = ForImage(1, Rotation("yaw", 0.02))(rng, state)
    rs = target.render(state.render_state, own.params, own.touched)
    assert rs.changed == (1,) and rs.states[0] is state.render_state.states[0]
    target.reject(rs)
    shared = ForImage(0, CoefficientWalk(Block.SHAPE, 0.1))(rng, state)
    rs = target.render(state.render_state, shared.params, shared.touched)
    assert rs.changed == (0, 1)
    target.reject(rs)


def test_cached_densities_follow_every_move(model, scenes):
    """After each step the chain's joint densities equal a fresh evaluation on new renderers."""
    truths, images = scenes
    target = _target(model, images)
    fresh = _target(model, images)
    linear = [linearise(im) for im in images]
    albedo = SharedAlbedoConditional(
        [RenderAlbedoData(f.renderer, lin) for f, lin in zip(target.faces, linear)], [SIGMA] * 2)
    moves = [(1.0, albedo)]
    for i in range(2):
        moves += [(1.0, ForImage(i, CoefficientWalk(Block.SHAPE, 0.1))),
                  (1.0, ForImage(i, CoefficientWalk(Block.ALBEDO, 0.1))),
                  (1.0, ForImage(i, CoefficientWalk(Block.EXPRESSION, 0.1))),
                  (1.0, ForImage(i, Rotation("yaw", 0.01))),
                  (1.0, ForImage(i, SHIntensity(0.05)))]
    proposal = mixture(*moves, name="joint")
    mismatches, accepted = [], []

    def check(k, state, info):
        accepted.append(info.accepted)
        again = init(state.params, fresh)
        if not math.isclose(again.log_posterior, state.log_posterior, rel_tol=1e-6):
            mismatches.append((k, info.proposal, again.log_posterior - state.log_posterior))
        first = state.params.images[0].momo
        for p, rs in zip(state.params.images, state.render_state.states):
            assert p.momo.shape is first.shape and p.momo.albedo is first.albedo
            assert rs.params is p
        assert state.render_state.changed == ()

    start = init(_start(truths), target)
    end = run(np.random.default_rng(1), start, target, proposal, 150, callback=check)
    assert not mismatches
    assert 0.05 < np.mean(accepted) < 0.95
    assert end.log_posterior > start.log_posterior
