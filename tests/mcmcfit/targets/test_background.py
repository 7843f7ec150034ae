"""The smoothed background density: proper, bounded by the foreground peak, and no reward for
shrinking the face."""

from __future__ import annotations

import math

import numpy as np
import pytest

from albedo_model.io.model_files import load_model
from albedo_model.render.renderer import Renderer
from mcmcfit.targets.background import colour_histogram
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.image import ImageLikelihood, prepare_image_target
from mcmcfit.targets.likelihoods import pixel_log_normaliser
from mcmcfit.targets.priors import LogPrior, PriorConfig
from mcmcfit.jobs.synthetic_case import synthetic_case

SIGMA = 0.043


@pytest.fixture(scope="module")
def hist():
    rng = np.random.default_rng(0)
    # a concentrated "skin" cluster (most pixels in a few bins) plus spread background
    skin = np.clip(rng.normal([0.45, 0.25, 0.15], 0.01, (6000, 3)), 0, 1)
    rest = rng.uniform(0, 1, (4000, 3))
    return colour_histogram(np.concatenate([skin, rest]), bins=25)


def test_raw_histogram_can_exceed_the_gaussian_peak_but_smoothed_never_does(hist):
    peak = pixel_log_normaliser(SIGMA)
    probe = np.array([[0.45, 0.25, 0.15], [0.46, 0.26, 0.14], [0.1, 0.9, 0.5]])
    assert hist.log_density(probe)[0] > peak  # the problem: bg beats a perfect fg
    grid = np.stack(np.meshgrid(*[np.linspace(0, 1, 41)] * 3, indexing="ij"), -1).reshape(-1, 3)
    smooth = hist.smoothed_log_density(np.concatenate([probe, grid]), SIGMA)
    assert np.all(np.isfinite(smooth)) and smooth.max() <= peak + 1e-9


def test_smoothed_density_integrates_to_one(hist):
    h = 0.02
    axis = np.arange(-0.25, 1.25 + h / 2, h)
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    total = np.exp(hist.smoothed_log_density(grid, SIGMA)).sum() * h**3
    assert total == pytest.approx(1.0, abs=0.01)


def test_smoothed_density_matches_a_monte_carlo_convolution(hist):
    rng = np.random.default_rng(1)
    # sample the histogram (uniform within bins) and add the noise
    p = (hist.counts / hist.total).reshape(-1)
    idx = rng.choice(p.size, 400000, p=p)
    ijk = np.stack(np.unravel_index(idx, hist.counts.shape), 1)
    y = (ijk + rng.uniform(0, 1, ijk.shape)) / hist.bins
    probe = np.array([[0.45, 0.25, 0.15], [0.3, 0.5, 0.7]])
    # density of y + noise at q = E_y[N(q; y, sigma^2 I)] (unbiased Monte Carlo)
    for q, got in zip(probe, np.exp(hist.smoothed_log_density(probe, SIGMA))):
        kernel = np.exp(-0.5 * np.sum((y - q) ** 2, 1) / SIGMA**2) / (
            (2 * math.pi) ** 1.5 * SIGMA**3)
        assert got == pytest.approx(kernel.mean(), rel=0.08)


@pytest.fixture(scope="module")
def default_model(default_model_file):
    return load_model(default_model_file)


@pytest.mark.embree
@pytest.mark.parametrize("seed", [0, 1])
def test_true_face_beats_shrunken_and_enlarged_faces(default_model, seed):
    case = synthetic_case(default_model, seed=seed)
    renderer = Renderer(default_model, threads=1)
    lik = ImageLikelihood(prepare_image_target(case.image, smooth_sigma=SIGMA), sigma=SIGMA)
    target = FaceTarget(renderer, lik, None, LogPrior(PriorConfig()))

    def score(scaling):
        p = case.truth._replace(pose=case.truth.pose._replace(scaling=scaling))
        return target.log_lik_image(target.init_render(p))

    truth = score(1.0)
    for s in (0.9, 0.97, 1.03, 1.1):
        assert truth > score(s), s
    # every face pixel of the true render gains over the background on average
    state = target.init_render(case.truth)
    n = int(np.asarray(state.pixel_hits.mask).sum())
    assert truth / n > 0.5
