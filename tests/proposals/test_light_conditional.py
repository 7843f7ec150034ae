"""The SH light's exact conditional: normal equations against brute force, moments of a Gibbs chain."""

from __future__ import annotations

import numpy as np
import pytest

from mh_chain import DropRatio, base_state, run_chain

from albedo_model.params import SHLight
from proposals.base import ProposalState
from proposals.light_conditional import LightConditional, LightSystem, light_system


def _problem(seed: int, n: int = 40, k: int = 9):
    rng = np.random.default_rng(seed)
    g = rng.uniform(0.0, 1.0, (n, 3, k))
    mat = np.eye(3) + rng.normal(0, 0.1, (3, 3))
    t = rng.uniform(0.1, 0.9, (n, 3))
    return g, mat, t


def test_normal_equations_match_the_explicit_design_matrix():
    g, mat, t = _problem(0)
    n, _, k = g.shape
    a = np.zeros((n, 3, 3 * k))  # A[p, c, 3 i + d] = M_cd G_pdi
    for c in range(3):
        for d in range(3):
            for i in range(k):
                a[:, c, 3 * i + d] = mat[c, d] * g[:, d, i]
    a = a.reshape(3 * n, 3 * k)
    system = light_system(g, mat, t)
    assert np.allclose(system.gram, a.T @ a)
    assert np.allclose(system.rhs, a.T @ t.reshape(-1))


def _toy(seed: int, sigma: float):
    """A linear-Gaussian light posterior with its exact mean and covariance."""
    g, mat, t = _problem(seed, n=15)
    system = light_system(g, mat, t)
    mu = np.zeros((9, 3))
    sd = np.full((9, 3), 0.7)
    prec = np.diag(1.0 / sd.reshape(-1) ** 2) + system.gram / sigma ** 2
    cov = np.linalg.inv(prec)
    mean = cov @ (system.rhs / sigma ** 2)

    def log_target(p):
        x = np.asarray(p.environment_map.coefficients).reshape(-1)
        return -0.5 * float((x - mean) @ prec @ (x - mean))

    return system, mu, sd, mean, cov, log_target


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gibbs_chain_has_the_exact_moments(seed):
    sigma = 0.3
    system, mu, sd, mean, cov, log_target = _toy(seed, sigma)
    proposal = LightConditional(lambda state: system._replace(key=("fixed",)), mu, sd,
                                sigma=sigma)
    start = base_state()._replace(environment_map=SHLight(np.zeros((9, 3))))
    x, acc = run_chain(proposal, log_target, start,
                       lambda p: np.asarray(p.environment_map.coefficients).reshape(-1), 3000,
                       seed)
    assert acc > 0.99  # an exact conditional is always accepted
    se = np.sqrt(np.diag(cov) / x.shape[0])
    assert np.max(np.abs(x.mean(0) - mean) / se) < 5.0
    assert np.allclose(x.var(0), np.diag(cov), rtol=0.15)


def test_negative_control_without_its_ratio_the_chain_has_wrong_variances():
    sigma = 0.3
    system, mu, sd, mean, cov, log_target = _toy(0, sigma)
    wrong = DropRatio(LightConditional(lambda s: system, mu, sd, sigma=sigma / 3))
    start = base_state()._replace(environment_map=SHLight(np.zeros((9, 3))))
    x, _ = run_chain(wrong, log_target, start,
                     lambda p: np.asarray(p.environment_map.coefficients).reshape(-1), 3000, 0)
    # without the ratio the chain targets pi x q, narrower than pi
    assert np.median(x.var(0) / np.diag(cov)) < 0.7


def test_without_data_the_move_is_the_identity():
    p = base_state()
    k = p.environment_map.coefficients.shape[0]
    proposal = LightConditional(lambda s: None, np.zeros((k, 3)), np.ones((k, 3)))
    move = proposal(np.random.default_rng(0), ProposalState(p))
    assert not move.touched and move.params is p


def test_an_empty_system_is_the_identity():
    p = base_state()
    k = p.environment_map.coefficients.shape[0]
    empty = LightSystem(np.zeros((3 * k, 3 * k)), np.zeros(3 * k), 0)
    move = LightConditional(lambda s: empty, np.zeros((k, 3)), np.ones((k, 3)))(
        np.random.default_rng(0), ProposalState(p))
    assert not move.touched
