"""The sensor noise of the encoded image, and the linearisation that is unbiased for it.

Truth here is analytic: the mean of ``x^2.2`` over Gaussian noise in ``x`` (Monte
Carlo with many draws), a least-squares gain whose true value is known, and
fields whose added noise is known.
"""

import numpy as np
import pytest

from albedo_model.shading.image_formation import GAMMA
from mcmcfit.targets.image import linearise, prepare_image_target
from mcmcfit.targets.noise_model import estimate_noise, fixed_noise, sensor_noise


def _encode_noisy(linear: np.ndarray, sigma: float, rng: np.random.Generator,
                  quantise: bool = True) -> np.ndarray:
    """A camera's image: the encoded intensity plus noise, clipped (and 8-bit)."""
    x = np.clip(linear ** (1.0 / GAMMA) + rng.normal(0.0, sigma, linear.shape), 0.0, 1.0)
    return np.round(x * 255.0) / 255.0 if quantise else x


@pytest.mark.parametrize("x0", [0.2, 0.5, 0.8])
def test_linearise_removes_the_noise_bias(x0):
    # sd of one linearised value ~2.2 x^1.2 sigma <= 0.044, 2e6 draws: standard error ~3e-5;
    # the bias at sigma 0.02 is 1.32 x^0.2 sigma^2 = 3.8e-4 .. 5.0e-4
    sigma = 0.02
    rng = np.random.default_rng(11)
    x = x0 + rng.normal(0.0, sigma, 2_000_000)
    truth = x0 ** GAMMA
    se = np.std(x ** GAMMA) / np.sqrt(x.size)
    plain = linearise(x).mean() - truth
    unbiased = linearise(x, sigma).mean() - truth
    predicted = 0.5 * GAMMA * (GAMMA - 1.0) * x0 ** (GAMMA - 2.0) * sigma ** 2
    assert plain == pytest.approx(predicted, rel=0.15)  # the bias the correction is for
    assert abs(unbiased) < 4 * se + 0.03 * predicted


def test_linearise_without_noise_is_the_plain_power_and_stays_non_negative():
    x = np.linspace(0.0, 1.0, 256)
    assert np.array_equal(linearise(x), linearise(x, 0.0))
    low = linearise(np.array([0.0, 1 / 255, 2 / 255]), 0.05)
    assert low[0] == 0.0 and np.all(low >= 0.0)


def test_a_gain_fitted_to_unbiased_intensities_is_unbiased():
    # y = a s over 20,000 pixels, noise of sd 0.01 in the encoded values, 8-bit; the gain's
    # least-squares estimate over 200 noise draws, in units of its standard error
    rng = np.random.default_rng(5)
    s = rng.uniform(0.1, 0.8, 20_000)
    a = 0.5
    z_plain, z_unbiased = [], []
    for _ in range(200):
        g = _encode_noisy(a * s, 0.01, rng)
        for y, out in ((linearise(g), z_plain), (linearise(g, 0.01), z_unbiased)):
            est = s @ y / (s @ s)
            se = np.sqrt(np.mean((y - est * s) ** 2) / (s @ s))
            out.append((est - a) / se)
    # mean of 200 z's: standard error <= 0.1 (their sd is about 1)
    assert np.mean(z_plain) > 1.0  # the plain linearisation's bias, several standard errors
    assert abs(np.mean(z_unbiased)) < 0.3


def _smooth_face(h: int = 96, w: int = 96) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    shade = 0.15 + 0.5 * np.exp(-((xx - 0.5) ** 2 + (yy - 0.45) ** 2) / 0.08)
    return np.stack([shade * c for c in (1.0, 0.75, 0.6)], axis=-1)


@pytest.mark.parametrize("sigma", [0.01, 0.02])
def test_sensor_noise_recovers_the_noise_of_the_encoded_image(sigma):
    render = _smooth_face()
    mask = np.ones(render.shape[:2], bool)
    found = []
    for seed in range(3):
        target = linearise(_encode_noisy(render, sigma, np.random.default_rng(seed),
                                         quantise=False))
        found.append(sensor_noise(target, render, mask))
    assert np.median(found) == pytest.approx(sigma, rel=0.1)


def test_model_error_does_not_pass_for_sensor_noise():
    # a 20 % gain error leaves a residual far above the noise: the wavelet bound holds
    render = _smooth_face()
    mask = np.ones(render.shape[:2], bool)
    target = linearise(_encode_noisy(render, 0.01, np.random.default_rng(3), quantise=False))
    noise = estimate_noise(target, 1.2 * render, mask)
    assert noise.sigma > 0.02
    assert noise.sensor_sigma == pytest.approx(0.01, rel=0.2)
    assert noise.to_dict()["sensor_sigma"] == pytest.approx(noise.sensor_sigma)


def test_sensor_noise_refuses_an_empty_mask_and_fixed_noise_has_none():
    render = _smooth_face(8, 8)
    with pytest.raises(ValueError, match="no pixel"):
        sensor_noise(render, render, np.zeros((8, 8), bool))
    assert fixed_noise(0.01, 1.0).sensor_sigma == 0.0


def test_the_target_is_linearised_for_the_noise_model_it_is_built_for():
    image = _encode_noisy(_smooth_face(), 0.01, np.random.default_rng(0))
    plain = prepare_image_target(image)
    unbiased = prepare_image_target(image, sensor_sigma=0.01)
    srgb = prepare_image_target(image, colour="srgb", sensor_sigma=0.01)
    assert np.array_equal(plain.linear, linearise(image))
    assert np.allclose(unbiased.linear, linearise(image, 0.01))
    assert np.all(unbiased.linear <= plain.linear)
    assert np.array_equal(srgb.linear, np.clip(image, 0.0, 1.0))  # encoded comparison: no bias
