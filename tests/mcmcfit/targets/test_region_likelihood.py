"""The Gaussian likelihood over a fixed pixel region: against a direct NumPy evaluation.

Every region pixel counts, hit or not (a miss has the renderer's background
colour), through the fused renderer path (the pixel set leaves misses out)
and through the plain Shaded path alike.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.errors import InputError
from albedo_model.params import MoMoCoefficients
from albedo_model.render.region import contour_jump, interior_region
from albedo_model.render.renderer import Renderer
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.image import ImageLikelihood, prepare_image_target
from mcmcfit.targets.likelihoods import pixel_log_normaliser
from mcmcfit.targets.priors import LogPrior

SIZE = 48
JUMP = contour_jump(7.5 / 2.0 * SIZE)  # the default camera's focal length in pixels


@pytest.fixture(scope="module")
def setup():
    model = small_face_model(subdivisions=4)
    truth = scene(SIZE, SIZE, yaw=0.2, coefficients=MoMoCoefficients(
        np.array([0.5, -0.3, 0.2, 0.1]), np.array([0.4, -0.2, 0.1]), np.array([0.3, -0.1])))
    image, _ = synthetic_target(model, truth)
    return model, truth, image


def _numpy(lik, rendered, region, sigma, temperature):
    lin = lik.target.linear.reshape(-1, 3)
    img = np.where(rendered.mask.reshape(-1)[:, None], rendered.image.reshape(-1, 3), 0.0)
    d2 = np.sum((img[region] - lin[region]) ** 2)
    n = int(region.sum())
    return (n * pixel_log_normaliser(sigma) - 0.5 * d2 / sigma ** 2) / temperature


@pytest.mark.parametrize("shift", [0.0, 20.0])
def test_region_likelihood_matches_numpy_with_hits_and_misses(setup, shift):
    model, truth, image = setup
    renderer = Renderer(model, specular=False, threads=1)
    base = renderer.render(truth)
    region = interior_region(base.state.prim_id, base.state.hits.t, SIZE, SIZE, erode=1,
                             jump=JUMP)
    # a region pixel far from the face too: a miss outside the renderer's pixel set
    region[0] = True
    target = prepare_image_target(image)
    sigma, temperature = 0.05, 3.0
    lik = ImageLikelihood(target, sigma=sigma, temperature=temperature, region=region)
    face = FaceTarget(renderer, lik, None, LogPrior())
    moved = truth._replace(pose=truth.pose._replace(
        translation=(shift, 0.0, truth.pose.translation[2])))
    state = face.init_render(moved)
    rendered = renderer.image(state)
    if shift:
        assert (region & (state.prim_id < 0)).sum() > 1  # some region pixels are misses now
    expected = _numpy(lik, rendered, region, sigma, temperature)
    assert face.log_lik_image(state) == pytest.approx(expected, rel=1e-5, abs=1e-2)
    assert lik(renderer.shade(state)) == pytest.approx(expected, rel=1e-5, abs=1e-2)
    assert lik.n_region == int(region.sum())


def test_region_likelihood_is_smooth_where_the_silhouette_one_jumps(setup):
    """Sub-pixel moves: over the region the value is smooth, over the render's pixels it jumps."""
    model, truth, image = setup
    renderer = Renderer(model, specular=False, threads=1)
    base = renderer.render(truth)
    region = interior_region(base.state.prim_id, base.state.hits.t, SIZE, SIZE, erode=2,
                             jump=JUMP)
    target = prepare_image_target(image)
    fixed = FaceTarget(renderer, ImageLikelihood(target, sigma=0.02, region=region), None,
                       LogPrior())
    covering = FaceTarget(renderer, ImageLikelihood(target, sigma=0.02), None, LogPrior())
    px_mm = 1000.0 / (7.5 / 2.0 * SIZE)  # mm per pixel at 1 m
    steps = np.linspace(-0.3, 0.3, 25) * px_mm

    def curve(face):
        out = []
        for dx in steps:
            p = truth._replace(pose=truth.pose._replace(translation=(dx, 0.0, -1000.0)))
            out.append(face.log_lik_image(face.init_render(p)))
        return np.array(out)

    def roughness(v):  # residual of a quartic fit, relative to the curve's range
        c = np.polyfit(steps, v, 4)
        return np.abs(v - np.polyval(c, steps)).max() / np.ptp(v)

    smooth, rough = roughness(curve(fixed)), roughness(curve(covering))
    assert smooth < 0.01, (smooth, rough)
    assert rough > 3 * smooth, (smooth, rough)


def test_region_needs_the_gaussian_and_the_image_size(setup):
    model, truth, image = setup
    target = prepare_image_target(image)
    with pytest.raises(InputError):
        ImageLikelihood(target, kind="trimmed", region=np.ones(SIZE * SIZE, bool))
    with pytest.raises(InputError):
        ImageLikelihood(target, region=np.ones(10, bool))
    lik = ImageLikelihood(target, region=np.ones(SIZE * SIZE, bool))
    with pytest.raises(InputError):
        lik.finish(np.zeros(SIZE), np.zeros(SIZE, np.int32))
    assert math.isfinite(lik.finish(np.zeros(SIZE), np.zeros(SIZE, np.int32),
                                    prim_id=np.zeros(SIZE * SIZE, int)))
