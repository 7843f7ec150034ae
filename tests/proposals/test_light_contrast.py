"""The contrast-light exchange: the light system under another colour matrix, and exact moments.

Truth: a linear render ``M(kappa) G L + o`` with Gaussian noise, priors
``kappa ~ N(1, 0.3^2)`` and ``L ~ N(mu, sd^2)``; the marginal of ``kappa``
(the light integrated out analytically) on a fine grid gives the exact
moments of ``kappa`` and of the light.
"""

from __future__ import annotations

import numpy as np
import pytest

from mh_chain import DropRatio, base_state, check_exchange_moments, grid_moments, run_chain

from albedo_model.params import Block, ColorTransform, SHLight
from proposals.base import ProposalState
from proposals.light_conditional import ContrastLightExchange, light_system, with_matrix

K = 4
SIGMA = 0.1
OFFSET = np.array([0.02, -0.01, 0.0])


def test_with_matrix_is_the_system_formed_under_that_matrix():
    rng = np.random.default_rng(3)
    g = rng.uniform(0.0, 1.0, (30, 3, K))
    t = rng.uniform(0.1, 0.9, (30, 3))
    a, b = ColorTransform(contrast=0.7).matrix(), ColorTransform(contrast=1.3).matrix()
    moved = with_matrix(light_system(g, a, t), b)
    direct = light_system(g, b, t)
    assert np.allclose(moved.gram, direct.gram) and np.allclose(moved.rhs, direct.rhs)
    held = light_system(g, a, t, matrix_free_target=False)
    with pytest.raises(ValueError):
        with_matrix(held, b)


def _problem(seed: int, n: int = 40):
    rng = np.random.default_rng(seed)
    g = rng.uniform(0.0, 0.6, (n, 3, K))
    mu, sd = np.zeros((K, 3)), np.full((K, 3), 0.5)
    light = rng.normal(0.0, 0.5, (K, 3)) + np.array([0.6, 0.5, 0.4])
    clean = np.einsum("pdi,id->pd", g, light)
    photo = clean @ ColorTransform(contrast=0.8).matrix().T + OFFSET + rng.normal(0, SIGMA,
                                                                                  (n, 3))

    def system(state):  # formed at the state's contrast, as the fit's data source does
        ct = state.params.color_transform
        return light_system(g, ct.matrix(), photo - OFFSET)._replace(key=(ct.contrast,))

    def log_target(p):
        ct = p.color_transform
        L = np.asarray(p.environment_map.coefficients, float)
        r = photo - OFFSET - np.einsum("pdi,id->pd", g, L) @ ct.matrix().T
        return (-0.5 * ((ct.contrast - 1.0) / 0.3) ** 2 - 0.5 * np.sum(((L - mu) / sd) ** 2)
                - 0.5 * float(np.sum(r * r)) / SIGMA**2)

    def marginal(kappa):  # log p(kappa | photo) + const, with L's conditional moments
        s = light_system(g, ColorTransform(contrast=kappa).matrix(), photo - OFFSET)
        prec0 = 1.0 / sd.reshape(-1) ** 2
        lam = np.diag(prec0) + s.gram / SIGMA**2
        h = prec0 * mu.reshape(-1) + s.rhs / SIGMA**2
        cov = np.linalg.inv(lam)
        m = cov @ h
        y = (photo - OFFSET).reshape(-1)
        return (-0.5 * ((kappa - 1.0) / 0.3) ** 2 - 0.5 * y @ y / SIGMA**2 + 0.5 * h @ m
                - 0.5 * np.linalg.slogdet(lam)[1]), m, cov

    moments = grid_moments(marginal, np.linspace(0.01, 2.5, 1000))
    return system, mu, sd, log_target, moments


def _chain(prop, log_target, seed, n=4000):
    start = base_state()._replace(environment_map=SHLight(np.zeros((K, 3))),
                                  color_transform=ColorTransform(contrast=1.0))
    return run_chain(prop, log_target, start, lambda p: np.r_[
        p.color_transform.contrast, np.asarray(p.environment_map.coefficients).reshape(-1)],
        n, seed)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_contrast_light_exchange_has_the_exact_moments(seed):
    system, mu, sd, log_target, (mean_k, var_k, mean_l, var_l) = _problem(seed)
    prop = ContrastLightExchange(system, mu, sd, sigma=SIGMA, step=2.0 * np.sqrt(var_k))
    x, acc = _chain(prop, log_target, seed)
    assert acc > 0.3  # a step of 2 marginal sds, accepted as a Metropolis step on kappa alone
    check_exchange_moments(x, mean_k, var_k, mean_l, var_l)


def test_contrast_light_exchange_negative_control_without_its_ratio():
    system, mu, sd, log_target, (_, var_k, _, var_l) = _problem(0)
    wrong = DropRatio(ContrastLightExchange(system, mu, sd, sigma=SIGMA,
                                            step=2.0 * np.sqrt(var_k)))
    x, _ = _chain(wrong, log_target, 0)
    # without the ratio the chain samples pi x q: the light too narrow
    assert np.median(x[500:, 1:].var(0) / var_l) < 0.7


def test_contrast_light_exchange_refuses_what_it_cannot_draw():
    system, mu, sd, _, _ = _problem(0)
    prop = ContrastLightExchange(system, mu, sd, sigma=SIGMA, step=0.1)
    assert prop.touches & Block.LIGHT and prop.touches & Block.COLOR_TRANSFORM
    flat = base_state()._replace(environment_map=SHLight(np.zeros((K, 3))),
                                 color_transform=ColorTransform(contrast=-0.2))
    mv = prop(np.random.default_rng(0), ProposalState(flat))
    assert mv.params is flat and not mv.touched
    held = ContrastLightExchange(lambda s: system(s)._replace(transport=None, cross=None), mu,
                                 sd, sigma=SIGMA, step=0.1)
    ok = flat._replace(color_transform=ColorTransform(contrast=1.0))
    mv = held(np.random.default_rng(0), ProposalState(ok))
    assert mv.params is ok and not mv.touched
    with pytest.raises(ValueError):
        ContrastLightExchange(system, mu, -sd, sigma=SIGMA)
