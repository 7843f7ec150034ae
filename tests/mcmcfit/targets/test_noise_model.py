"""The per-image noise model: RMS residual and correlation area against analytic fields."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.ndimage as ndi

from mcmcfit.targets.noise_model import (
    MIN_SIGMA, NoiseModel, correlation_area, estimate_noise, fixed_noise,
)


def _mask(h: int = 200, w: int = 200) -> np.ndarray:
    yy, xx = np.indices((h, w))
    return (yy - h / 2) ** 2 / 80 ** 2 + (xx - w / 2) ** 2 / 60 ** 2 < 1


def test_white_noise_has_unit_correlation_area():
    rng = np.random.default_rng(0)
    areas = [correlation_area(rng.normal(size=(200, 200, 3)), _mask()) for _ in range(5)]
    assert abs(np.median(areas) - 1.0) < 0.1


@pytest.mark.parametrize("s", [1.0, 2.0])
def test_gaussian_smoothed_noise_has_the_analytic_area(s):
    # white noise smoothed by a Gaussian of sd s has a Gaussian autocorrelation of
    # sd s sqrt(2): its integral over the plane is 2 pi (s sqrt 2)^2 = 4 pi s^2
    rng = np.random.default_rng(1)
    areas = []
    for _ in range(6):
        x = rng.normal(size=(200, 200, 3))
        x = np.stack([ndi.gaussian_filter(x[..., c], s) for c in range(3)], -1)
        areas.append(correlation_area(x, _mask()))
    expected = 4 * math.pi * s * s
    assert abs(np.median(areas) / expected - 1.0) < 0.25


def test_estimate_recovers_sigma_of_white_residuals_on_the_face_only():
    rng = np.random.default_rng(2)
    m = _mask()
    target = rng.uniform(0.2, 0.6, (200, 200, 3))
    render = target + rng.normal(0, 0.02, target.shape)
    render[~m] = 5.0  # the background is never read
    noise = estimate_noise(target, render, m)
    assert noise.source == "estimated" and noise.n_face == int(m.sum())
    assert abs(noise.sigma / 0.02 - 1.0) < 0.02
    assert noise.temperature < 1.2
    assert math.isclose(noise.n_effective, noise.n_face / noise.temperature)


def test_a_perfect_render_is_floored_and_clipped_pixels_are_excluded():
    m = _mask()
    target = np.full((200, 200, 3), 0.5)
    noise = estimate_noise(target, target.copy(), m)
    assert noise.sigma == MIN_SIGMA and noise.temperature >= 1.0
    usable = np.ones_like(m)
    usable[:100] = False
    half = estimate_noise(target, target, m, usable=usable)
    assert half.n_face == int((m & usable).sum())


def test_no_face_pixel_is_an_error_and_fixed_is_reported_as_given():
    with pytest.raises(ValueError):
        estimate_noise(np.zeros((8, 8, 3)), np.zeros((8, 8, 3)), np.zeros((8, 8), bool))
    d = fixed_noise(0.043, 40.0).to_dict()
    assert d["source"] == "fixed" and d["n_effective"] is None and "configuration" in d["rule"]
    assert isinstance(NoiseModel(0.01, 2.0, "estimated", 10, 5.0).to_dict()["rule"], str)
