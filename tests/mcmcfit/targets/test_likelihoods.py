"""Likelihood values against hand computation: constants, histogram background, pixel models,
landmarks with visibility, face box."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from face_factory import scene, small_face_model

from albedo_model.errors import InputError
from albedo_model.io.tlms import Landmark
from albedo_model.shading.image_formation import Shaded
from mcmcfit.targets.background import colour_histogram
from mcmcfit.targets.image import ImageLikelihood, linearise, prepare_image_target
from mcmcfit.targets.landmarks import LandmarkGeometry, LandmarkTarget
from mcmcfit.targets.likelihoods import (
    face_box_log_lik,
    finish_independent,
    independent_terms,
    landmark_log_lik,
    pixel_log_normaliser,
)

SIGMA = 0.043


def test_pixel_constant_is_the_correct_three_dimensional_normaliser():
    assert pixel_log_normaliser(SIGMA) == pytest.approx(6.683, abs=1e-3)
    # scalismo's 3/2 == 1 integer-division bug gives 7.602; we are 1/2 log 2 pi below it
    buggy = -math.log(2 * math.pi) - 3 * math.log(SIGMA)
    assert buggy == pytest.approx(7.602, abs=1e-3)
    assert buggy - pixel_log_normaliser(SIGMA) == pytest.approx(0.5 * math.log(2 * math.pi))
    # the Gaussian it normalises integrates to 1 (3-D, separable)
    x = np.linspace(-8 * SIGMA, 8 * SIGMA, 4001)
    one_d = np.trapezoid(np.exp(-x**2 / (2 * SIGMA**2)), x)
    assert math.exp(pixel_log_normaliser(SIGMA)) * one_d**3 == pytest.approx(1.0, rel=1e-9)


def test_histogram_background_by_hand():
    colours = np.array([[0.0, 0.0, 0.0], [0.01, 0.02, 0.03], [1.0, 1.0, 1.0], [0.5, 0.5, 0.5]])
    h = colour_histogram(colours, bins=25)
    assert h.total == 4 and h.counts.sum() == 4
    assert h.counts[0, 0, 0] == 2 and h.counts[24, 24, 24] == 1 and h.counts[12, 12, 12] == 1
    got = h.log_density(np.array([[0.02, 0.03, 0.001], [0.999, 1.0, 0.97], [0.3, 0.3, 0.3]]))
    assert got[0] == pytest.approx(math.log(2 / 4) + 3 * math.log(25))
    assert got[1] == pytest.approx(math.log(1 / 4) + 3 * math.log(25))
    assert got[2] == -math.inf
    # a normalised density: sum over bins of exp(log density) * bin volume = 1
    centres = (np.arange(25) + 0.5) / 25
    grid = np.stack(np.meshgrid(centres, centres, centres, indexing="ij"), -1).reshape(-1, 3)
    assert np.sum(np.exp(h.log_density(grid))) / 25**3 == pytest.approx(1.0)
    with pytest.raises(InputError):
        colour_histogram(np.array([[1.2, 0.0, 0.0]]))


def _random_case(rng, h=5, w=7, face=0.6):
    target = rng.uniform(0, 1, (h, w, 3))
    render = np.clip(target + rng.normal(0, 0.05, target.shape), 0, 1)
    mask = rng.random((h, w)) < face
    return target, render, mask


def _shaded(render, mask):
    return Shaded(rgb=tuple(jnp.asarray(render[..., c].reshape(-1), jnp.float32) for c in range(3)),
                  mask=jnp.asarray(mask.reshape(-1)))


def test_independent_likelihood_by_hand():
    rng = np.random.default_rng(0)
    srgb, render, mask = _random_case(rng)
    tgt = prepare_image_target(srgb, bins=25)
    lin = linearise(srgb)
    bg = colour_histogram(lin, bins=25).log_density(lin)
    expected = 0.0
    for i, j in zip(*np.nonzero(mask)):
        d2 = np.sum((lin[i, j] - render[i, j]) ** 2)
        fg = -1.5 * math.log(2 * math.pi) - 3 * math.log(SIGMA) - d2 / (2 * SIGMA**2)
        expected += fg - bg[i, j]
    got = ImageLikelihood(tgt, kind="independent", sigma=SIGMA)(_shaded(render, mask))
    assert got == pytest.approx(expected, rel=1e-5, abs=1e-3)


def test_linearisation_is_the_pure_power():
    x = np.array([0.0, 0.2, 0.5, 1.0, 1.3, -0.1])
    assert np.allclose(linearise(x), [0.0, 0.2**2.2, 0.5**2.2, 1.0, 1.0, 0.0])


def test_collective_and_trimmed_by_hand():
    rng = np.random.default_rng(1)
    srgb, render, mask = _random_case(rng)
    tgt = prepare_image_target(srgb)
    lin = linearise(srgb)
    bg = colour_histogram(lin, bins=25).log_density(lin)
    d2 = np.sum((lin - render) ** 2, -1)[mask]
    n = d2.size
    m = d2.sum() / (3 * SIGMA**2 * n)  # RMS distance sqrt(3) sigma
    z = (m - 1) / math.sqrt((2 / 3) / n)
    clt = ImageLikelihood(tgt, kind="collective", sigma=SIGMA)(_shaded(render, mask))
    assert clt == pytest.approx(-0.5 * math.log(2 * math.pi) - z * z / 2, rel=1e-5)
    vals = pixel_log_normaliser(SIGMA) - d2 / (2 * SIGMA**2) - bg[mask]
    k = int(0.7 * n)
    trimmed = ImageLikelihood(tgt, kind="trimmed", sigma=SIGMA, trim_fraction=0.7)
    assert trimmed(_shaded(render, mask)) == pytest.approx(np.sort(vals)[::-1][:k].sum(),
                                                           rel=1e-5)


@pytest.mark.parametrize("kind", ["independent", "collective", "trimmed"])
def test_nothing_rendered_is_minus_infinity(kind):
    rng = np.random.default_rng(2)
    srgb, render, _ = _random_case(rng)
    lik = ImageLikelihood(prepare_image_target(srgb), kind=kind)
    assert lik(_shaded(render, np.zeros(srgb.shape[:2], bool))) == -math.inf


def test_row_sums_in_float64_keep_precision_at_250_squared():
    """~31k face pixels with realistic residuals (|l| ~ 1.3e5, where the float32 quantum is
    8e-3): row sums + float64 agree with a float64 evaluation of the same float32 inputs to
    1e-3 (measured 6e-5..4e-4; a single float32 sum was off by 3e-3..6e-3)."""
    for seed in range(3):
        rng = np.random.default_rng(seed)
        srgb = rng.uniform(0, 1, (250, 250, 3))
        tgt = prepare_image_target(srgb)
        render = (tgt.linear + rng.normal(0, SIGMA, srgb.shape)).astype(np.float32)
        mask = rng.random((250, 250)) < 0.5
        sh = _shaded(render, mask)
        rows, counts = independent_terms(sh.rgb, sh.mask, tgt.arrays, jnp.float32(SIGMA))
        got = finish_independent(np.asarray(rows), np.asarray(counts), SIGMA)
        s32 = np.float32(SIGMA)
        inv = float(np.float32(0.5) / (s32 * s32))  # the device uses sigma in float32
        d2 = np.sum((render.astype(np.float64) - tgt.linear.astype(np.float32)) ** 2, -1)
        per_pixel = -d2 * inv - np.asarray(tgt.arrays.bg, np.float64)
        exact = mask.sum() * pixel_log_normaliser(SIGMA) + per_pixel[mask].sum()
        assert abs(exact) > 1e5
        assert abs(got - exact) < 1e-3


@pytest.mark.parametrize("kind", ["independent", "collective", "trimmed"])
def test_pixel_set_terms_equal_whole_image_terms(kind):
    """On a renderer's pixel set (every face pixel and some misses, whole rows' worth) the
    likelihood is the whole image's: what pixel_set_fn computes inside a fused program."""
    rng = np.random.default_rng(5)
    srgb, render, mask = _random_case(rng, h=12, w=9, face=0.4)
    h, w = mask.shape
    tgt = prepare_image_target(srgb)
    lik = ImageLikelihood(tgt, kind=kind, sigma=SIGMA, trim_fraction=0.8)
    whole = lik(_shaded(render, mask))
    hit = mask.ravel()
    select = hit.copy()
    extra = (-(-hit.sum() // w) + 1) * w - hit.sum()  # a multiple of the width, some misses
    select[np.flatnonzero(~hit)[:extra]] = True
    pixels = np.flatnonzero(select).astype(np.int32)
    assert len(pixels) % w == 0 and len(pixels) < h * w
    flat = render.reshape(-1, 3)[pixels]
    rgb = tuple(jnp.asarray(flat[:, c]) for c in range(3))
    terms = lik.pixel_set_fn(rgb, jnp.asarray(hit[pixels]), jnp.asarray(pixels),
                             *lik.device_args())
    assert lik.finish(*terms) == pytest.approx(whole, rel=1e-6)


def test_landmark_log_lik_by_hand_with_hidden_term():
    pred = np.array([[10.0, 10.0], [20.0, 25.0], [0.0, 0.0]])
    obs = np.array([[13.0, 14.0], [20.0, 25.0], [50.0, 50.0]])
    vis = np.array([True, True, False])
    hidden = -math.log(64 * 48)
    expected = (2 * (-math.log(2 * math.pi) - 2 * math.log(4.0)) - 25.0 / (2 * 16.0) + hidden)
    assert landmark_log_lik(pred, obs, vis, 4.0, hidden) == pytest.approx(expected)


@pytest.fixture(scope="module")
def small_model():
    return small_face_model()


def test_landmark_target_is_visibility_aware(small_model):
    """Frontal view: the back of the head is hidden and scores log(0.05) - log(WH) whatever its
    click;
    unknown and occluded-annotated landmarks are dropped; the rest is the Gaussian sum."""
    params = scene(64, 64)
    geo = LandmarkGeometry(small_model)
    names = ["left.eye.corner_outer", "center.nose.tip", "center.back.of.head"]
    pts = geo.points(names, params)
    from albedo_model.camera import project
    px, _ = project(pts, params.pose, params.view, params.camera, params.image_size)
    clicks = [Landmark(n, tuple(p + [1.0, -2.0])) for n, p in zip(names, px)]
    clicks += [Landmark("no.such.landmark", (3.0, 3.0)),
               Landmark("right.eye.corner_outer", (5.0, 5.0), visible=False)]
    t = LandmarkTarget(geo, clicks, sigma=4.0, image_size=params.image_size)
    assert t.names == names and t.unknown == ["no.such.landmark"]
    _, vis = t.project(params)
    assert vis.tolist() == [True, True, False]
    gauss = -math.log(2 * math.pi) - 2 * math.log(4.0) - 5.0 / 32.0
    assert t.log_lik(params) == pytest.approx(2 * gauss + math.log(0.05) - math.log(64 * 64))
    # moving the hidden landmark's click changes nothing
    clicks[2] = Landmark("center.back.of.head", (60.0, 1.0))
    t2 = LandmarkTarget(geo, clicks, sigma=4.0, image_size=params.image_size)
    assert t2.log_lik(params) == pytest.approx(t.log_lik(params))
    # turned around (yaw pi), the back of the head becomes visible and the face hidden
    _, vis_back = t.project(scene(64, 64, yaw=math.pi))
    assert vis_back.tolist() == [False, False, True]
    with pytest.raises(InputError, match="none of the"):
        LandmarkTarget(geo, {"no.such.landmark": (1.0, 2.0)}, image_size=params.image_size)


def test_face_box_by_hand():
    pts = {"left.eye.corner_outer": (70.0, 40.0), "left.eye.corner_inner": (60.0, 40.0),
           "right.eye.corner_outer": (30.0, 40.0), "right.eye.corner_inner": (40.0, 40.0),
           "left.lips.corner": (60.0, 80.0), "right.lips.corner": (40.0, 80.0),
           "center.nose.tip": (52.0, 60.0)}
    box = (20.0, 20.0, 80.0, 100.0)  # diagonal 100, centre (50, 60)
    # eye-eye 30, eyes-lips 40 -> s = 40 / (100 / 3) = 1.2; centre offset (2, 0) / 100
    ls = math.log(1.2)
    expected = (-0.5 * math.log(2 * math.pi) - math.log(0.1) - 0.5 * (ls / 0.1) ** 2
                - math.log(2 * math.pi) - 2 * math.log(0.1) - 0.5 * 0.02**2 / 0.01)
    assert face_box_log_lik(pts, box) == pytest.approx(expected)
