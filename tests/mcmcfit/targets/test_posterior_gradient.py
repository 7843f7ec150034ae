"""The posterior gradient of a face fit: values, derivatives against finite differences, MALA on it.

Small synthetic face (``face_factory``, 64x64): the prior and landmark
gradients against central differences of the target's own factors; the image
gradient against central differences of the sampler's image likelihood on a
view that the face fills (no silhouette inside the image, so the exact
likelihood is smooth there); and MALA moves through the sampler's kernel.
"""

from __future__ import annotations

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.errors import InputError
from albedo_model.params import Block, ImageSize, MoMoCoefficients, SHLight
from albedo_model.render.renderer import Renderer
from mcmcfit.sampling.kernel import init, run
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.gradient import posterior_gradient
from mcmcfit.targets.image import ImageLikelihood, prepare_image_target
from mcmcfit.targets.landmarks import (
    FaceBoxTarget,
    LandmarkGeometry,
    LandmarkTarget,
    face_box_names,
    face_box_of,
)
from mcmcfit.targets.priors import LogPrior
from proposals.gradient import MALA, block_vector, with_block_vector

ALL = Block.SHAPE | Block.EXPRESSION | Block.POSE | Block.CAMERA
SIZE = 64


@pytest.fixture(scope="module")
def model():
    return small_face_model(subdivisions=4)


def _truth(**kw):
    rng = np.random.default_rng(5)
    coeffs = MoMoCoefficients(rng.normal(size=4), rng.normal(size=3), rng.normal(0, 0.7, 2))
    p = scene(SIZE, SIZE, coefficients=coeffs, **kw)
    light = SHLight(SHLight.frontal().coefficients + rng.normal(0, 0.03, (9, 3)))
    return p._replace(environment_map=light)


def _target(model, truth, *, temperature=1.0, kind="independent", landmarks=True):
    image, clicked = synthetic_target(model, truth, specular=False)
    lm = None
    if landmarks:
        lm = LandmarkTarget(LandmarkGeometry(model, threads=1), clicked, sigma=2.0,
                            image_size=ImageSize(SIZE, SIZE))
    lik = ImageLikelihood(prepare_image_target(image, smooth_sigma=0.043), kind=kind,
                          sigma=0.043, temperature=temperature)
    # no specular term: half the compile time (its derivatives are checked in
    # tests/albedo_model/render/test_differentiable.py)
    return FaceTarget(Renderer(model, specular=False, threads=1), lik, lm, LogPrior())


def _perturbed(params, rng, scale=1.0):
    x = block_vector(params, ALL)
    step = np.concatenate([rng.normal(0, 0.3, 4), rng.normal(0, 0.3, 2),
                           rng.normal(0, 0.03, 3), rng.normal(0, 4.0, 3), rng.normal(0, 0.1, 1)])
    return with_block_vector(params, ALL, x + scale * step)


def _central(f, params, blocks, h):
    x = block_vector(params, blocks)
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        up, down = x.copy(), x.copy()
        up[i] += h[i]
        down[i] -= h[i]
        out[i] = (f(with_block_vector(params, blocks, up))
                  - f(with_block_vector(params, blocks, down))) / (2 * h[i])
    return out


def _steps(params):
    """Finite-difference steps per flat entry: coefficients, angles, mm, focal length."""
    return np.concatenate([np.full(4, 1e-3), np.full(2, 1e-3), np.full(3, 1e-4),
                           np.full(3, 1e-2), np.full(1, 1e-4)])


def test_values_are_the_targets_and_the_sampler_renderer_is_untouched(model):
    truth = _truth(yaw=0.2)
    target = _target(model, truth, temperature=40.0)
    p = _perturbed(truth, np.random.default_rng(0))
    state = init(p, target)
    before = target.renderer.image(state.render_state).image.copy()
    grad = posterior_gradient(target, ALL)
    parts = grad.parts(_perturbed(truth, np.random.default_rng(1)))  # elsewhere: own cast
    parts = grad.parts(p)
    assert parts.log_prior == state.log_prior and parts.log_lik_lm == state.log_lik_lm
    assert parts.log_lik_img == pytest.approx(state.log_lik_img, rel=1e-5, abs=1e-3)
    value, g = grad(p)
    assert value == pytest.approx(state.log_posterior, rel=1e-5, abs=1e-3)
    assert g.shape == (13,) and np.all(np.isfinite(g))
    # the sampler's accepted scene still renders (and steps from) its own state
    np.testing.assert_array_equal(target.renderer.image(state.render_state).image, before)
    moved = _perturbed(p, np.random.default_rng(2), 0.1)
    rs = target.render(state.render_state, moved, ALL)
    fresh = Renderer(model, specular=False, threads=1).render(moved).image
    np.testing.assert_allclose(target.renderer.image(rs).image, fresh, atol=1e-4)
    target.reject(rs)
    # a subset of blocks is the matching part of the whole vector
    _, g_pose = posterior_gradient(target, Block.POSE | Block.CAMERA)(p)
    np.testing.assert_allclose(g_pose, g[6:], rtol=1e-6)
    with pytest.raises(InputError):
        posterior_gradient(target, Block.LIGHT)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_prior_and_landmark_gradients_match_central_differences(model, seed):
    truth = _truth(yaw=0.3 * (seed - 1))
    target = _target(model, truth)
    p = _perturbed(truth, np.random.default_rng(seed))
    parts = posterior_gradient(target, ALL).parts(p)
    h = _steps(p)

    def flat(g):
        return np.concatenate([np.ravel(a) for a in g])

    fd_prior = _central(target.log_prior, p, ALL, h)
    np.testing.assert_allclose(flat(parts.prior), fd_prior, rtol=1e-6, atol=1e-8)
    fd_lm = _central(target.log_lik_landmarks, p, ALL, h)
    assert np.abs(fd_lm).max() > 1.0  # the perturbation moved the landmarks off their clicks
    np.testing.assert_allclose(flat(parts.landmarks), fd_lm, rtol=1e-4,
                               atol=1e-5 * np.abs(fd_lm).max())


@pytest.mark.parametrize("seed,kind", [(0, "independent"), (1, "independent"),
                                       (2, "collective"), (3, "trimmed")])
def test_image_gradient_matches_differences_of_the_sampler_likelihood(model, seed, kind):
    """A close-up that the face fills: the exact image likelihood has no silhouette to jump at."""
    truth = _truth(focal=30.0, translation=(0.0, 10.0, -700.0))
    target = _target(model, truth, kind=kind, landmarks=False)
    p = _perturbed(truth, np.random.default_rng(seed), 0.3)
    grad = posterior_gradient(target, ALL)
    parts = grad.parts(p)
    assert parts.face_pixels == SIZE * SIZE

    def log_lik_img(q):
        return target.log_lik_image(target.init_render(q))

    h = 20 * _steps(p)  # float32 likelihoods: larger steps than for the exact factors
    fd = _central(log_lik_img, p, ALL, h)
    g = np.concatenate([np.ravel(a) for a in parts.image])
    scale = np.abs(fd).max()
    assert scale > 10.0
    # measured: within 0.2-1 % of the largest entry (triangle crossings are kinks; float32)
    np.testing.assert_allclose(g, fd, rtol=0.03, atol=0.01 * scale)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mala_moves_raise_the_posterior_from_a_perturbed_start(model, seed):
    truth = _truth(yaw=0.25)
    target = _target(model, truth, temperature=10.0)
    start = _perturbed(truth, np.random.default_rng(100 + seed), 2.0)
    grad = posterior_gradient(target, ALL)
    diag = np.concatenate([np.full(6, 0.05), np.full(3, 1e-4), np.full(3, 4.0), [1e-3]])
    mala = MALA(grad, ALL, 0.5, diag)
    state = init(start, target)
    accepted = []
    end = run(np.random.default_rng(seed), state, target, mala, 25,
              callback=lambda i, s, info: accepted.append(info.accepted))
    assert sum(accepted) >= 5
    assert end.log_posterior > state.log_posterior + 50.0, (state.log_posterior,
                                                           end.log_posterior)


def test_a_face_box_factor_is_differentiated_by_central_differences(model):
    """Factors other than clicked landmarks (here a face box) take the finite-difference path."""
    truth = _truth(yaw=0.1)
    target = _target(model, truth, landmarks=False)
    geometry = LandmarkGeometry(model, threads=1)
    names = face_box_names(geometry)
    px = LandmarkTarget(geometry, {n: (0.0, 0.0) for n in names}, image_size=ImageSize(SIZE, SIZE)
                        ).project(truth)[0]
    box = face_box_of(px) + np.array([-2.0, 1.0, 3.0, 2.0])
    target.landmarks = FaceBoxTarget(geometry, box)
    p = _perturbed(truth, np.random.default_rng(7), 0.5)
    parts = posterior_gradient(target, ALL).parts(p)
    assert parts.log_lik_lm == target.log_lik_landmarks(p)
    fd = _central(target.log_lik_landmarks, p, ALL, 10 * _steps(p))
    g = np.concatenate([np.ravel(a) for a in parts.landmarks])
    assert np.abs(fd).max() > 1.0
    np.testing.assert_allclose(g, fd, rtol=1e-3, atol=1e-4 * np.abs(fd).max())
