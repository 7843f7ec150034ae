"""SH light proposals and the specular-exponent proposal: invariants, Jacobians, stationarity."""

from __future__ import annotations

import numpy as np
import pytest
from mh_chain import DropRatio, assert_moments, base_state, moment_errors, run_chain
from scipy import stats

from albedo_model.params import Block, SHLight
from proposals.base import ProposalState, mixture
from proposals.light import (
    SHBandMixer,
    SHColorShift,
    SHIntensity,
    SHPerturbation,
    SHSpatial,
    SpecularExponentScaling,
)

N = 12_000


def _state(L):
    return base_state()._replace(environment_map=SHLight(np.asarray(L, float)))


def _L(p):
    return p.environment_map.coefficients


def _std_normal(p):
    L = _L(p)
    return -0.5 * float(np.sum(L * L))


def _start(k=9, seed=0):
    return _state(np.random.default_rng(seed).normal(size=(k, 3)))


def test_intensity_scales_everything_with_ratio_27_log_s():
    p = _start()
    move = SHIntensity(0.1)(np.random.default_rng(1), ProposalState(p))
    s = _L(move.params) / _L(p)
    np.testing.assert_allclose(s, s[0, 0], rtol=1e-12)
    assert move.log_q_ratio == pytest.approx(27 * np.log(s[0, 0]), rel=1e-12)
    zero = SHIntensity(0.1)(np.random.default_rng(1), ProposalState(_state(np.zeros((9, 3)))))
    assert zero.touched == Block.NONE


def test_intensity_alone_samples_the_chi_radius():
    feat = lambda p: [float(np.sum(_L(p) ** 2))]  # noqa: E731
    prop = SHIntensity(0.25)
    samples, _ = run_chain(prop, _std_normal, _start(), feat, N, seed=2)
    assert_moments(samples, 27, np.sqrt(54))
    wrong, _ = run_chain(DropRatio(prop), _std_normal, _start(), feat, N // 2, seed=2)
    assert moment_errors(wrong, 27, np.sqrt(54)).max() > 0.15


def test_band_mixer_alone_samples_each_band_radius():
    dims = np.array([3, 9, 15])  # 3 (2l + 1) coefficients per band
    feat = lambda p: [float(np.sum(_L(p)[b * b:(b + 1) ** 2] ** 2)) for b in range(3)]  # noqa: E731
    prop = SHBandMixer(0.4)
    samples, _ = run_chain(prop, _std_normal, _start(), feat, N, seed=3)
    assert_moments(samples, dims, np.sqrt(2 * dims))
    wrong, _ = run_chain(DropRatio(prop), _std_normal, _start(), feat, N // 2, seed=3)
    assert moment_errors(wrong, dims, np.sqrt(2 * dims)).max() > 0.15


def test_band_mixer_leaves_a_zero_band_alone():
    L = SHLight.frontal().coefficients  # band 2 is zero
    move = SHBandMixer(0.1)(np.random.default_rng(4), ProposalState(_state(L)))
    assert not np.any(_L(move.params)[4:])
    s0, s1 = _L(move.params)[0, 0] / L[0, 0], _L(move.params)[2, 0] / L[2, 0]
    assert move.log_q_ratio == pytest.approx(3 * np.log(s0) + 9 * np.log(s1), rel=1e-12)


def _sphere_cosine_moments(kappa, n):
    """Mean and sd of t = mu_hat . x_hat for a vMF-like density exp(kappa t) on S^(n-1)."""
    t = np.linspace(-1, 1, 400_001)[1:-1]
    logw = kappa * t + 0.5 * (n - 3) * np.log1p(-t * t)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    m = (w * t).sum()
    return m, np.sqrt((w * (t - m) ** 2).sum())


def test_energy_preserving_perturbation_is_symmetric_on_the_sphere():
    """Alone, it samples N(mu, I) restricted to the sphere: exp(mu . x), a vMF law."""
    p = _start(seed=5)
    R = np.linalg.norm(_L(p))
    mu = np.random.default_rng(6).normal(size=(9, 3))
    mu *= 2.0 / np.linalg.norm(mu)
    prop = SHPerturbation(0.4, fix_energy=True)
    move = prop(np.random.default_rng(7), ProposalState(p))
    assert move.log_q_ratio == 0.0
    assert np.linalg.norm(_L(move.params)) == pytest.approx(R, rel=1e-12)
    log_p = lambda q: -0.5 * float(np.sum((_L(q) - mu) ** 2))  # noqa: E731
    feat = lambda q: [float(np.sum(_L(q) * mu)) / (R * 2.0)]  # noqa: E731
    samples, _ = run_chain(prop, log_p, p, feat, N, seed=8)
    assert_moments(samples, *_sphere_cosine_moments(2.0 * R, 27))


def _colour_shift_map(z, n):
    """T(x, delta) = (c (x + 1 delta), -c delta) on R^(n+3), rows of 3."""
    x, d = z[:n].reshape(-1, 3), z[n:]
    y = x + d
    c = np.linalg.norm(x) / np.linalg.norm(y)
    return np.concatenate([(c * y).ravel(), -c * d])


def test_colour_shift_jacobian_is_c_to_the_n_plus_3():
    rng = np.random.default_rng(9)
    for n in (12, 27):
        z = np.concatenate([rng.normal(size=n), rng.normal(0, 0.4, 3)])
        h = 1e-6
        jac = np.empty((n + 3, n + 3))
        for j in range(n + 3):
            e = np.zeros(n + 3)
            e[j] = h
            jac[:, j] = (_colour_shift_map(z + e, n) - _colour_shift_map(z - e, n)) / (2 * h)
        x, d = z[:n].reshape(-1, 3), z[n:]
        c = np.linalg.norm(x) / np.linalg.norm(x + d)
        assert abs(np.linalg.det(jac)) == pytest.approx(c ** (n + 3), rel=1e-6)
        # T is an involution
        np.testing.assert_allclose(_colour_shift_map(_colour_shift_map(z, n), n), z, atol=1e-12)


def test_colour_shift_move_and_ratio():
    p = _start(seed=10)
    sigma = 0.3
    rng = np.random.default_rng(11)
    delta = np.random.default_rng(11).normal(0, sigma, 3)
    move = SHColorShift(sigma)(rng, ProposalState(p))
    L, L_new = _L(p), _L(move.params)
    c = np.linalg.norm(L) / np.linalg.norm(L + delta)
    np.testing.assert_allclose(L_new, c * (L + delta), rtol=1e-12)
    assert np.linalg.norm(L_new) == pytest.approx(np.linalg.norm(L), rel=1e-12)
    expected = -(c * c - 1) * delta @ delta / (2 * sigma**2) + 30 * np.log(c)
    assert move.log_q_ratio == pytest.approx(expected, rel=1e-10)


def test_colour_shift_alone_samples_its_leaf():
    """Under N(0, I_n), u = |x_perp|^2 / |x|^2 ~ Beta((n - 3)/2, 3/2) on every leaf.

    x_perp is the part orthogonal to the three "same colour in every row" directions,
    the move keeps |x| and the direction of x_perp and moves u.
    """
    n = 27

    def u(p):
        L = _L(p)
        perp = L - L.mean(0)
        return [float(np.sum(perp**2) / np.sum(L**2))]

    beta = stats.beta((n - 3) / 2, 1.5)
    prop = SHColorShift(0.4)
    samples, acc = run_chain(prop, _std_normal, _start(seed=12), u, N, seed=13)
    assert acc > 0.2
    assert_moments(samples, beta.mean(), beta.std())
    wrong, _ = run_chain(DropRatio(prop), _std_normal, _start(seed=12), u, N // 2, seed=13)
    assert moment_errors(wrong, beta.mean(), beta.std()).max() > 0.15


def test_spatial_adds_grey_per_coefficient():
    p = _start(seed=14)
    move = SHSpatial(0.1)(np.random.default_rng(15), ProposalState(p))
    diff = _L(move.params) - _L(p)
    np.testing.assert_allclose(diff, diff[:, :1].repeat(3, 1), atol=1e-15)
    assert move.log_q_ratio == 0.0 and np.all(diff != 0)


def test_reference_light_mixture_samples_a_gaussian():
    """All five reference kinds together (test-sized scales) on N(m, diag s^2), K = 4.

    A plain walk is added for mixing; checked are the standardised coordinates and
    their squared norm (chi^2 with 12 degrees of freedom), which has a large ESS.
    """
    rng = np.random.default_rng(16)
    m, s = rng.normal(0, 1, (4, 3)), rng.uniform(0.5, 1.0, (4, 3))
    prop = mixture((1.0, SHSpatial(0.5)), (1.0, SHBandMixer(0.2)), (1.0, SHIntensity(0.1)),
                   (1.0, SHPerturbation(0.4, fix_energy=True)), (1.0, SHColorShift(0.3)),
                   (2.0, SHPerturbation(0.35, fix_energy=False)))
    log_p = lambda p: -0.5 * float(np.sum(((_L(p) - m) / s) ** 2))  # noqa: E731

    def feat(p):
        z = ((_L(p) - m) / s).ravel()
        return [float(z @ z), *z]

    samples, _ = run_chain(prop, log_p, _state(m), feat, 20_000, seed=17)
    assert_moments(samples[:, :1], 12, np.sqrt(24))
    assert_moments(samples[:, 1:], 0.0, 1.0, min_ess=60)
    wrong = mixture(*((w, DropRatio(c)) for w, c in zip(prop.weights, prop.components)))
    samples, _ = run_chain(wrong, log_p, _state(m), feat, 10_000, seed=17)
    assert moment_errors(samples[:, :1], 12, np.sqrt(24)).max() > 0.15


def test_specular_exponent_chain_matches_lognormal():
    def log_p(p):
        e = p.specular_exponent
        return -0.5 * ((np.log(e) - np.log(15.0)) / 0.4) ** 2 - np.log(e)

    prop = mixture((0.5, SpecularExponentScaling(0.5)), (0.5, SpecularExponentScaling(0.1)))
    feat = lambda p: [np.log(p.specular_exponent)]  # noqa: E731
    samples, _ = run_chain(prop, log_p, base_state(), feat, N, seed=18)
    assert_moments(samples, np.log(15.0), 0.4)
    wrong, _ = run_chain(DropRatio(prop), log_p, base_state(), feat, N // 2, seed=18)
    assert moment_errors(wrong, np.log(15.0), 0.4).max() > 0.15
    move = prop(np.random.default_rng(0), ProposalState(base_state()))
    assert move.touched == Block.SPECULAR_EXPONENT
    assert move.log_q_ratio == pytest.approx(np.log(move.params.specular_exponent / 20.0))
