"""The posterior's gradient and Gauss-Newton precision over a pixel region, and the climb to the mode.

Small synthetic face (``face_factory``, 56x56): the prior and landmark parts
against central differences of the target's own factors; the image gradient
(reverse mode) against the Gauss-Newton gradient (forward mode) and against
central differences of the sampler's exact region likelihood; the climb to the
mode (Levenberg-Marquardt) from a perturbed start, and the Laplace approximation.
"""

from __future__ import annotations

import numpy as np
import pytest
from face_factory import random_lit_face, small_face_model

from albedo_model.params import ImageSize, SHLight
from albedo_model.render.region import contour_jump, interior_region
from albedo_model.render.renderer import Renderer
from albedo_model.scene_vector import SceneLayout
from mcmcfit.fitting.mode import find_mode, laplace
from mcmcfit.sampling.kernel import init
from mcmcfit.targets.curvature import PosteriorCurvature, coordinate_gradient, prior_curvature
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.image import ImageLikelihood, prepare_image_target
from mcmcfit.targets.landmarks import LandmarkGeometry, LandmarkTarget
from mcmcfit.targets.priors import LogPrior
from proposals.laplace.coordinates import SamplingCoordinates

SIZE = 56
SIGMA = 0.03


@pytest.fixture(scope="module")
def problem():
    model = small_face_model(subdivisions=4)
    rng = np.random.default_rng(5)
    truth, image, clicked = random_lit_face(model, rng, SIZE, yaw=0.15, pitch=-0.05)
    renderer = Renderer(model, specular=False, threads=1)
    base = renderer.render(truth)
    region = interior_region(base.state.prim_id, base.state.hits.t, SIZE, SIZE, erode=2,
                             jump=contour_jump(7.5 / 2.0 * SIZE))
    lm = LandmarkTarget(LandmarkGeometry(model, threads=1), clicked, sigma=2.0,
                        image_size=ImageSize(SIZE, SIZE))
    lik = ImageLikelihood(prepare_image_target(image), sigma=SIGMA, region=region)
    face = FaceTarget(renderer, lik, lm, LogPrior())
    lay = SceneLayout.for_params(truth)
    return model, truth, face, lay, PosteriorCurvature(face, lay)


def _fd(f, x, lay, params, i, h):
    up, down = x.copy(), x.copy()
    up[i] += h
    down[i] -= h
    return (f(lay.with_vector(params, up)) - f(lay.with_vector(params, down))) / (2 * h)


def test_prior_gradient_and_precision_are_the_priors(problem):
    _, truth, face, lay, _ = problem
    p = truth._replace(color_transform=truth.color_transform._replace(gain=(1.1, 0.9, 1.2)),
                       specular_exponent=14.0)
    g, prec = prior_curvature(p, lay, face.prior.config)
    x = lay.vector(p)
    for i in range(lay.size):
        h = 1e-4 * max(1.0, abs(x[i]))
        assert g[i] == pytest.approx(_fd(face.prior, x, lay, p, i, h), rel=1e-4, abs=1e-6)
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        second = (face.prior(lay.with_vector(p, up)) - 2 * face.prior(p)
                  + face.prior(lay.with_vector(p, down))) / h ** 2
        assert prec[i, i] == pytest.approx(-second, rel=1e-3, abs=1e-4)


def test_landmark_gradient_is_the_landmark_likelihoods(problem):
    _, truth, face, lay, cur = problem
    p = truth._replace(pose=truth.pose._replace(yaw=truth.pose.yaw + 0.02,
                                                translation=(3.0, -2.0, -1000.0)))
    g = cur.landmarks(p).gradient
    x = lay.vector(p)
    sl = lay.slices()
    for name in ("shape", "expression", "angles", "translation", "focal_length",
                 "principal_point"):
        for i in range(sl[name].start, sl[name].stop):
            h = 1e-5 * max(1.0, abs(x[i]))
            assert g[i] == pytest.approx(_fd(face.log_lik_landmarks, x, lay, p, i, h),
                                         rel=1e-3, abs=1e-3)
    assert not np.any(g[sl["albedo"]]) and not np.any(g[sl["light"]])


def test_value_and_gradient_is_the_sum_of_its_parts(problem):
    """The HMC path (one landmark projection, a reverse-mode landmark pullback) equals the parts."""
    _, truth, face, lay, cur = problem
    p = truth._replace(pose=truth.pose._replace(yaw=truth.pose.yaw + 0.02,
                                                translation=(3.0, -2.0, -1000.0)))
    value, grad = cur.value_and_gradient(p)
    v_img, g_img = cur.image_gradient(p)
    g_prior, _ = prior_curvature(p, lay, face.prior.config)
    assert value == pytest.approx(v_img + face.log_lik_landmarks(p) + face.log_prior(p),
                                  rel=1e-9, abs=1e-9)
    np.testing.assert_allclose(grad, g_img + cur.landmarks(p).gradient + g_prior,
                               rtol=1e-9, atol=1e-9 * np.abs(grad).max())


def test_image_gradient_forward_reverse_and_finite_differences(problem):
    _, truth, face, lay, cur = problem
    p = truth._replace(pose=truth.pose._replace(translation=(0.5, -0.3, -1000.0)))
    _, g_rev = cur.image_gradient(p)
    g_fwd = cur.image(p).gradient
    np.testing.assert_allclose(g_rev, g_fwd, rtol=0, atol=2e-3 * np.abs(g_fwd).max())

    def img(params):
        return face.log_lik_image(face.init_render(params))

    x = lay.vector(p)
    rng = np.random.default_rng(1)
    for _ in range(4):  # directional derivatives along random smallish directions
        d = rng.normal(size=lay.size) * np.where(np.abs(x) > 10, 1e-3 * np.abs(x), 1e-3)
        fd = (img(lay.with_vector(p, x + d)) - img(lay.with_vector(p, x - d))) / 2
        assert g_rev @ d == pytest.approx(fd, rel=0.05, abs=0.05)


@pytest.mark.parametrize("exact_gradient", [False, True], ids=["subset", "exact-gradient"])
def test_climb_reaches_the_mode_and_laplace_is_positive_definite(problem, exact_gradient):
    """Both climbs: each step's gradient from a pixel subset, or the exact one with a kept precision."""
    _, truth, face, lay, cur = problem
    coords = SamplingCoordinates(lay, truth)
    start = truth._replace(
        pose=truth.pose._replace(yaw=truth.pose.yaw + 0.04, translation=(4.0, 3.0, -1020.0)),
        environment_map=SHLight(truth.environment_map.coefficients * 1.2))
    res = find_mode(face, cur, coords, start, rng=np.random.default_rng(0), max_steps=15,
                    gradient=coordinate_gradient(cur, coords) if exact_gradient else None)
    assert res.iterations >= 2 and all(b >= a for a, b in zip(res.trace, res.trace[1:]))
    exact_truth = init(truth, face).log_posterior + coords.log_jacobian(coords.u_of(truth))
    assert res.log_density > exact_truth - 5.0  # the mode is at least as good as the truth
    p = res.params
    assert abs(p.pose.yaw - truth.pose.yaw) < 0.01
    assert np.allclose(p.pose.translation[:2], truth.pose.translation[:2], atol=1.0)
    approx = laplace(cur, coords, p)
    assert np.all(np.linalg.eigvalsh(approx.precision) > 0)
    u = coords.u_of(p)
    z = np.linalg.solve(approx.chol_cov, approx.mean - u)
    assert np.linalg.norm(z) < 5.0  # the Newton step from the mode is small in sds
    grad = coordinate_gradient(cur, coords)
    value, g = grad(p)
    assert np.isfinite(value) and g.shape == (coords.size,)


@pytest.mark.parametrize("exact_gradient", [False, True], ids=["subset", "exact-gradient"])
def test_climb_with_held_coordinates_moves_only_the_free_ones(problem, exact_gradient):
    """The appearance-only climb: geometry held exactly, the appearance's conditional mode reached."""
    from mcmcfit.fitting.gaussian_stage import appearance_coordinates

    _, truth, face, lay, cur = problem
    coords = SamplingCoordinates(lay, truth)
    start = truth._replace(environment_map=SHLight(truth.environment_map.coefficients * 1.3))
    free = appearance_coordinates(coords)
    assert free.any() and not free.all()
    res = find_mode(face, cur, coords, start, rng=np.random.default_rng(0), max_steps=15,
                    free=free,
                    gradient=coordinate_gradient(cur, coords) if exact_gradient else None)
    u0, u1 = coords.u_of(start), coords.u_of(res.params)
    np.testing.assert_array_equal(u1[~free], u0[~free])
    assert res.iterations >= 1 and res.log_density > res.trace[0]
    # the geometry is the truth's: the conditional mode is at least as good as the truth
    exact_truth = init(truth, face).log_posterior + coords.log_jacobian(coords.u_of(truth))
    assert res.trace[0] < exact_truth - 20.0 < res.log_density
