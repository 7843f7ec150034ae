"""Every prior factor is a normalised density of the parameter as stored (1-D quadrature)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from albedo_model.params import MoMoCoefficients, SHLight, default_square, fit_to_image_size
from mcmcfit.targets.priors import LogPrior, PriorConfig, std_normal_logpdf

PRIOR = LogPrior()
BASE = fit_to_image_size(default_square(), 64, 64)._replace(
    momo=MoMoCoefficients.zeros(3, 2, 1))


def _unit_entry(i, c):
    e = np.zeros((9, 3))
    e[i, c] = 1.0
    return e


def _pose(**kw):
    return lambda x: BASE._replace(pose=BASE.pose._replace(**{k: f(x) for k, f in kw.items()}))


def _color(field):
    def make(x):
        ct = BASE.color_transform
        if field == "contrast":
            return BASE._replace(color_transform=ct._replace(contrast=x))
        vals = list(getattr(ct, field))
        vals[1] = x
        return BASE._replace(color_transform=ct._replace(**{field: tuple(vals)}))
    return make


CASES = {
    # factor: (params of x, grid)
    "yaw": (_pose(yaw=lambda x: x), np.linspace(-8, 8, 4001)),
    "pitch": (_pose(pitch=lambda x: x), np.linspace(-6, 6, 4001)),
    "roll": (_pose(roll=lambda x: x), np.linspace(-3, 3, 4001)),
    "translation_x": (_pose(translation=lambda x: (x, 0.0, -1000.0)), np.linspace(-3e3, 3e3, 4001)),
    "translation_y": (_pose(translation=lambda x: (0.0, x, -1000.0)), np.linspace(-3e3, 3e3, 4001)),
    "distance": (_pose(translation=lambda x: (0.0, 0.0, -x)), np.geomspace(1e-1, 1e6, 4001)),
    "focal_length": (lambda x: BASE._replace(camera=BASE.camera._replace(focal_length=x)),
                     np.geomspace(1e-3, 1e4, 4001)),
    "principal_point_x": (lambda x: BASE._replace(camera=BASE.camera._replace(
        principal_point=(x, 0.0))), np.linspace(-5, 5, 4001)),
    "color_transform_contrast": (_color("contrast"), np.linspace(-2, 4, 4001)),
    "color_transform_offset": (_color("offset"), np.linspace(-1, 1, 4001)),
    "color_transform_gain": (_color("gain"), np.geomspace(1e-4, 1e3, 4001)),
    "specular_exponent": (lambda x: BASE._replace(specular_exponent=x),
                          np.geomspace(1e-2, 1e5, 4001)),
    "shape": (lambda x: BASE._replace(momo=BASE.momo._replace(shape=np.array([0.0, x, 0.0]))),
              np.linspace(-9, 9, 4001)),
    "light": (lambda x: BASE._replace(environment_map=SHLight(
        SHLight.frontal().coefficients + _unit_entry(4, 1) * x)), np.linspace(-5, 5, 4001)),
}


@pytest.mark.parametrize("factor", sorted(CASES))
def test_factor_integrates_to_one(factor):
    make, grid = CASES[factor]
    at = np.array([PRIOR.terms(make(x))[factor] for x in grid])
    rest = PRIOR.terms(make(grid[len(grid) // 2]))[factor] - PRIOR.terms(make(grid[0]))[factor]
    assert np.isfinite(rest)
    # the other coordinates of a multi-coordinate factor contribute a constant density
    const = {"color_transform_offset": 2, "color_transform_gain": 2, "shape": 2, "light": 26}.get(factor, 0)
    if const:
        other = PRIOR.terms(make(grid[len(grid) // 2]))[factor]
        # density of the moved coordinate alone = factor minus the others (evaluated at x = mode)
        at = at - (other - _one_d_at_mode(factor, make, grid))
    assert np.trapezoid(np.exp(at), grid) == pytest.approx(1.0, abs=2e-4)


def _one_d_at_mode(factor, make, grid):
    """Log density of the moved coordinate alone at the middle grid point (analytic)."""
    c = PriorConfig()
    x = grid[len(grid) // 2]
    if factor == "color_transform_offset":
        s = c.offset_sigma
        return -0.5 * math.log(2 * math.pi) - math.log(s) - 0.5 * (x / s) ** 2
    if factor == "color_transform_gain":
        s = c.gain_log_sigma
        return -0.5 * math.log(2 * math.pi) - math.log(s) - 0.5 * (math.log(x) / s) ** 2 - math.log(x)
    if factor == "shape":
        return -0.5 * math.log(2 * math.pi) - 0.5 * x * x
    s = c.light_band_sigma[2]  # coefficient 4 is in band 2
    return -0.5 * math.log(2 * math.pi) - math.log(s) - 0.5 * (x / s) ** 2


def test_coefficient_prior_is_the_normalised_standard_normal():
    c = np.array([0.3, -1.2, 2.0])
    assert std_normal_logpdf(c) == pytest.approx(
        -1.5 * math.log(2 * math.pi) - 0.5 * float(c @ c))
    assert std_normal_logpdf(np.zeros(0)) == 0.0


def test_total_is_the_sum_of_the_factors_and_never_nan():
    t = PRIOR.terms(BASE)
    assert PRIOR(BASE) == pytest.approx(math.fsum(t.values()))
    bad = BASE._replace(camera=BASE.camera._replace(focal_length=-1.0))
    assert PRIOR(bad) == -math.inf
    behind = BASE._replace(pose=BASE.pose._replace(translation=(0.0, 0.0, 10.0)))
    assert PRIOR(behind) == -math.inf


def test_directional_light_factor_integrates_to_one_over_its_chart():
    """The directional light's direction factor is a density in (azimuth, elevation): 2-D quadrature.

    With the strengths held, the factor minus their log-normal densities must
    integrate to 1 over ``|az| < pi, |el| < pi/2`` (the sphere, with cos el).
    """
    from albedo_model.params import DirectionalLight
    from mcmcfit.targets.priors import directional_prior, lognormal_logpdf

    c = PriorConfig()
    az = np.linspace(-math.pi, math.pi, 721)
    el = np.linspace(-math.pi / 2 + 1e-9, math.pi / 2 - 1e-9, 361)
    strength = (0.4, 0.5, 0.6)
    rest = sum(lognormal_logpdf(s, c.directional_median, c.directional_log_sigma) for s in strength)
    dens = np.array([[math.exp(directional_prior((a, e), strength, c)[0] - rest) for e in el]
                     for a in az])
    total = np.trapezoid(np.trapezoid(dens, el, axis=1), az)
    assert total == pytest.approx(1.0, abs=1e-3)
    light = DirectionalLight.from_angles(0.3, 0.2, strength)
    assert PRIOR.terms(BASE._replace(directional_light=light))["directional_light"] == pytest.approx(
        directional_prior((0.3, 0.2), strength, c)[0])
    assert "directional_light" not in PRIOR.terms(BASE)  # off: no factor


def test_directional_light_prior_gradient_and_precision_match_differences():
    """The gradient and diagonal precision the climbs read are the log density's derivatives."""
    from mcmcfit.targets.priors import directional_prior

    c = PriorConfig()
    x0 = np.array([0.4, 0.25, 0.3, 0.5, 0.8])

    def f(x):
        return directional_prior(x[:2], x[2:], c)[0]

    _, grad, hess = directional_prior(x0[:2], x0[2:], c)
    for i in range(5):
        h = 1e-5
        e = np.zeros(5)
        e[i] = h
        assert grad[i] == pytest.approx((f(x0 + e) - f(x0 - e)) / (2 * h), rel=1e-5, abs=1e-7)
        second = (f(x0 + e) - 2 * f(x0) + f(x0 - e)) / (h * h)
        assert hess[i] == pytest.approx(max(-second, 1e-6), rel=1e-3, abs=1e-4)
