"""The robust foreground: a pixel is the face or an occluder, the label summed out.

Checked against independent arithmetic: the device terms against the mixture
written out on the host in float64, the gradients (the Gauss-Newton one with
the pixels' face probabilities as weights, and the reverse-mode read-out)
against finite differences of the exact likelihood, and the EM of the scale
against residuals drawn with a known sigma and outlier fraction.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from face_factory import random_lit_face, small_face_model, synthetic_target

from albedo_model.errors import InputError
from albedo_model.render.region import contour_jump, interior_region
from albedo_model.render.renderer import Renderer
from albedo_model.scene_vector import SceneLayout
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.joint_fit import fit_joint
from mcmcfit.targets.background import occluder_log_density
from mcmcfit.targets.curvature import PosteriorCurvature
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.image import ImageLikelihood, prepare_image_target
from mcmcfit.targets.noise_model import MIN_OUTLIER, robust_noise
from mcmcfit.targets.priors import LogPrior
from mcmcfit.targets.robust_foreground import robust_logs, robust_pixel_values

SIZE = 56
SIGMA = 0.03
EPS = 0.1
TEMPERATURE = 3.0


@pytest.fixture(scope="module")
def occluded():
    """A small face with a square occluder of random colours over its upper half."""
    model = small_face_model(subdivisions=4)
    rng = np.random.default_rng(7)
    truth, image, _ = random_lit_face(model, rng, SIZE, yaw=0.1, pitch=-0.05)
    image[14:26, 18:38] = rng.uniform(0.0, 1.0, (12, 20, 3))
    renderer = Renderer(model, specular=False, threads=1)
    base = renderer.render(truth)
    region = interior_region(base.state.prim_id, base.state.hits.t, SIZE, SIZE, erode=2,
                             jump=contour_jump(7.5 / 2.0 * SIZE))
    target = prepare_image_target(image, smooth_sigma=SIGMA)
    lik = ImageLikelihood(target, sigma=SIGMA, region=region, temperature=TEMPERATURE,
                          outlier_probability=EPS)
    face = FaceTarget(renderer, lik, None, LogPrior())
    lay = SceneLayout.for_params(truth)
    return model, truth, face, lay, PosteriorCurvature(face, lay), region


@pytest.mark.parametrize("per_pixel", [False, True])
def test_robust_terms_equal_the_mixture_written_out(occluded, per_pixel):
    """Device rows + host misses = sum over the region of log((1-e) N + e h) / T, float64.

    With one outlier probability for all pixels and with a map of them.
    """
    _, truth, face, _, _, region = occluded
    eps = (np.random.default_rng(2).uniform(0.01, 0.5, SIZE * SIZE) if per_pixel else EPS)
    lik = ImageLikelihood(face.image_likelihood.target, sigma=SIGMA, region=region,
                          temperature=TEMPERATURE, outlier_probability=eps)
    face = FaceTarget(face.renderer, lik, None, LogPrior())
    moved = truth._replace(pose=truth.pose._replace(translation=(12.0, -4.0, -1000.0)))
    rendered = face.renderer.render(moved)
    colours = np.where(rendered.mask[..., None], rendered.image, 0.0).reshape(-1, 3)
    pix = np.flatnonzero(region.reshape(-1))
    s32 = float(np.float32(SIGMA))
    face_log, out_log = robust_logs(s32, np.broadcast_to(eps, (SIZE * SIZE,))[pix],
                                    np.asarray(lik.target.arrays.bg).reshape(-1)[pix])
    expected = robust_pixel_values(colours[pix], lik.target.linear.reshape(-1, 3)[pix],
                                   face_log, out_log, s32).sum() / TEMPERATURE
    assert np.count_nonzero(~rendered.mask.reshape(-1)[pix]) > 0  # misses are covered too
    assert face.log_lik_image(face.init_render(moved)) == pytest.approx(expected, rel=2e-5)


def _log_lik(face, target, region, shaded, eps: float = 0.0) -> float:
    lik = ImageLikelihood(target, sigma=SIGMA, region=region, temperature=TEMPERATURE,
                          outlier_probability=eps)
    return FaceTarget(face.renderer, lik, None, LogPrior()).log_lik_image(shaded)


def test_a_vanishing_outlier_probability_is_the_gaussian(occluded):
    """Without an occluder, eps = 1e-30 is the Gaussian; with one, robust scores it far higher."""
    model, truth, face, _, _, region = occluded
    shaded = face.init_render(truth)
    clean = prepare_image_target(synthetic_target(model, truth, specular=False)[0],
                                 smooth_sigma=SIGMA)
    assert _log_lik(face, clean, region, shaded, 1e-30) == pytest.approx(
        _log_lik(face, clean, region, shaded), rel=1e-5)
    target = face.image_likelihood.target
    assert _log_lik(face, target, region, shaded, EPS) > _log_lik(
        face, target, region, shaded) + 100.0


def test_robust_gradients_match_finite_differences(occluded):
    """Gauss-Newton (face-probability weights) and reverse-mode gradients vs central differences."""
    _, truth, face, lay, cur, _ = occluded
    p = truth._replace(pose=truth.pose._replace(translation=(0.5, -0.3, -1000.0)))
    g_fwd = cur.image(p).gradient
    _, g_rev = cur.image_gradient(p)
    np.testing.assert_allclose(g_rev, g_fwd, rtol=0, atol=2e-3 * np.abs(g_fwd).max())

    def img(params):
        return face.log_lik_image(face.init_render(params))

    x = lay.vector(p)
    rng = np.random.default_rng(3)
    for _ in range(4):
        d = rng.normal(size=lay.size) * np.where(np.abs(x) > 10, 1e-3 * np.abs(x), 1e-3)
        fd = (img(lay.with_vector(p, x + d)) - img(lay.with_vector(p, x - d))) / 2
        assert g_fwd @ d == pytest.approx(fd, rel=0.05, abs=0.05)
        assert g_rev @ d == pytest.approx(fd, rel=0.05, abs=0.05)


def _residuals(rng, shape, sigma: float, occluder: np.ndarray):
    """Residuals (H, W, 3) and background (H, W): face ~ N(0, sigma^2), occluder uniform colours."""
    target = rng.uniform(0.2, 0.8, shape + (3,))
    face = target + rng.normal(0.0, sigma, shape + (3,))
    colours = np.where(occluder[..., None], rng.uniform(0.0, 1.0, shape + (3,)), face)
    return colours - target, np.zeros(shape)  # uniform colours: density 1 on the unit cube


def test_em_finds_a_coherent_occluder_and_the_noise():
    """A block occluding 20 % of a 120 x 120 region, sigma 0.02, 4 seeds.

    sigma within 5 %; at least 95 % of the block's pixels more likely occluder
    than face and at most 1 % of the rest; the occlusion prior is high inside
    the block (> 0.8 away from its edge) and low outside (< 0.1 away from it).
    """
    shape = (120, 120)
    block = np.zeros(shape, bool)
    block[10:64, 20:73] = True  # 2862 pixels: ~20 %
    inner, outer = np.zeros(shape, bool), np.ones(shape, bool)
    inner[20:54, 30:63] = True
    outer[0:74, 10:83] = False
    for seed in range(4):
        res, bg = _residuals(np.random.default_rng(seed), shape, 0.02, block)
        sigma, prior, face = robust_noise(res, bg, np.ones(shape, bool))
        assert sigma == pytest.approx(0.02, rel=0.05)
        assert np.mean(face[block] < 0.5) >= 0.95
        assert np.mean(face[~block] < 0.5) <= 0.01
        assert prior[inner].min() > 0.8 and prior[outer].max() < 0.1


def test_em_without_occluders_keeps_the_floor():
    """Negative control: Gaussian residuals only give the prior's floor and the plain RMS."""
    shape = (100, 100)
    for seed in range(4):
        res, bg = _residuals(np.random.default_rng(10 + seed), shape, 0.02,
                             np.zeros(shape, bool))
        sigma, prior, face = robust_noise(res, bg, np.ones(shape, bool))
        assert prior.max() <= MIN_OUTLIER + 0.005
        assert np.mean(face < 0.5) <= 0.001
        assert sigma == pytest.approx(math.sqrt(np.mean(res ** 2)), rel=0.03)


def test_bad_robust_settings_are_refused(occluded):
    _, _, face, _, _, _ = occluded
    with pytest.raises(InputError, match="region"):
        ImageLikelihood(face.image_likelihood.target, outlier_probability=0.1)
    with pytest.raises(InputError, match="outlier probability"):
        ImageLikelihood(face.image_likelihood.target, outlier_probability=1.0,
                        region=face.image_likelihood.region)
    with pytest.raises(InputError, match="gaussian sampler"):
        FitConfig(foreground="robust", sampler="random-walk")
    with pytest.raises(InputError, match="outlier_probability"):
        FitConfig(outlier_probability=0.0)
    with pytest.raises(InputError, match="joint fit"):
        fit_joint([np.zeros((8, 8, 3))] * 2, [None, None], small_face_model(),
                  config=FitConfig(foreground="robust"))


def test_the_occluder_density_is_the_colours_outside_the_face():
    """A colour found only inside the face scores far below one found outside it."""
    image = np.full((40, 40, 3), 0.6)  # skin inside
    image[:, :10] = (0.1, 0.05, 0.02)  # dark hair outside
    outside = np.zeros((40, 40), bool)
    outside[:, :10] = True
    dens = occluder_log_density(image, outside, bins=10)
    assert dens[0, 0] > dens[20, 20] + 10.0
    smooth = occluder_log_density(image, outside, bins=10, sigma=0.02)
    assert smooth[0, 0] > smooth[20, 20] + 10.0 and np.all(np.isfinite(smooth))
    # with almost nothing outside, the whole image's colours
    few = np.zeros((40, 40), bool)
    few[0, :5] = True
    whole = occluder_log_density(image, few, bins=10)
    assert whole[20, 20] > whole[0, 0]
