"""The SH least-squares light solver and its independence proposal."""

from __future__ import annotations

import numpy as np
import pytest
from mh_chain import DropRatio, assert_moments, base_state, moment_errors, run_chain

from albedo_model.errors import InputError
from albedo_model.params import Block, SHLight
from albedo_model.sh import LAMBERT_FACTORS, sh_basis, sh_irradiance
from proposals.light_solver import SHLightSolver, solve_sh_light
from proposals.base import ProposalState


def _scene(p, seed=0, noise=0.0):
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(p, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    albedo = rng.uniform(0.2, 0.9, (p, 3))
    light = SHLight.frontal().coefficients + rng.normal(0, 0.1, (9, 3))
    target = albedo * sh_irradiance(light, normals) + rng.normal(0, noise, (p, 3))
    return normals, albedo, target, light


def test_recovers_a_known_light_exactly_without_noise():
    normals, albedo, target, light = _scene(400)
    np.testing.assert_allclose(solve_sh_light(normals, albedo, target, ridge=1e-14), light,
                               atol=1e-8)
    # unnormalised normals, a zero normal and a NaN row are handled
    scaled = np.vstack([normals * 3.0, np.zeros((1, 3)), np.full((1, 3), np.nan)])
    alb = np.vstack([albedo, np.ones((2, 3))])
    tgt = np.vstack([target, np.ones((2, 3))])
    np.testing.assert_allclose(solve_sh_light(scaled, alb, tgt, ridge=1e-14), light, atol=1e-8)


def test_few_points_are_regularised_and_match_the_ridge_normal_equations():
    normals, albedo, target, _ = _scene(3, seed=1)
    ridge = 1e-3
    L = solve_sh_light(normals, albedo, target, ridge=ridge)
    assert L.shape == (9, 3) and np.all(np.isfinite(L))
    basis = sh_basis(normals) * LAMBERT_FACTORS
    for c in range(3):
        x = albedo[:, c:c + 1] * basis
        expected = np.linalg.solve(x.T @ x + ridge * 3 * np.eye(9), x.T @ target[:, c])
        np.testing.assert_allclose(L[:, c], expected, rtol=1e-7, atol=1e-9)
    with pytest.raises(InputError, match="singular"):
        solve_sh_light(normals, albedo, target, ridge=0.0)
    with pytest.raises(InputError, match=r"\(P, 3\)"):
        solve_sh_light(normals, albedo[:2], target)
    np.testing.assert_array_equal(solve_sh_light(np.zeros((0, 3)), np.zeros((0, 3)),
                                                 np.zeros((0, 3))), np.zeros((9, 3)))


def test_proposal_ratio_is_the_gaussian_independence_ratio():
    normals, albedo, target, _ = _scene(100, seed=2, noise=0.01)
    prop = SHLightSolver(lambda p: (normals, albedo, target), sigma=0.02, ridge=1e-4)
    p = base_state()
    mu = solve_sh_light(normals, albedo, target, ridge=1e-4)
    move = prop(np.random.default_rng(3), ProposalState(p))
    L, L_new = p.environment_map.coefficients, move.params.environment_map.coefficients
    expected = (np.sum((L_new - mu) ** 2) - np.sum((L - mu) ** 2)) / (2 * 0.02**2)
    assert move.log_q_ratio == pytest.approx(expected, rel=1e-12)
    assert move.touched == Block.LIGHT == prop.touches
    empty = SHLightSolver(lambda p: (np.zeros((0, 3)),) * 3)(np.random.default_rng(0), ProposalState(p))
    assert empty.touched == Block.NONE and empty.params is p
    with pytest.raises(InputError, match=r"\(9, 3\)"):
        prop(np.random.default_rng(0), ProposalState(p._replace(environment_map=SHLight(np.ones((4, 3))))))


def test_independence_chain_samples_a_gaussian_light_posterior():
    """MH with the solver proposal alone samples N(m, s^2 I) on the 27 coefficients."""
    normals, albedo, target, _ = _scene(30, seed=4, noise=0.01)
    mu = solve_sh_light(normals, albedo, target, ridge=1e-4)
    m = mu + np.random.default_rng(5).normal(0, 0.003, (9, 3))  # target centre, off mu
    s = 0.02
    prop = SHLightSolver(lambda p: (normals, albedo, target), sigma=0.022, ridge=1e-4)
    log_p = lambda p: -0.5 * float(np.sum(((p.environment_map.coefficients - m) / s) ** 2))  # noqa: E731

    def feat(p):
        z = ((p.environment_map.coefficients - m) / s).ravel()
        return [float(z @ z), *z[:6]]

    n_steps = 4000  # an independence sampler mixes fast; each step solves the LS system
    samples, acc = run_chain(prop, log_p, base_state(), feat, n_steps, seed=6)
    assert acc > 0.3
    assert_moments(samples[:, :1], 27, np.sqrt(54), burn=500)
    assert_moments(samples[:, 1:], 0.0, 1.0, burn=500)
    wrong, _ = run_chain(DropRatio(prop), log_p, base_state(), feat, n_steps // 2, seed=6)
    assert moment_errors(wrong[:, :1], 27, np.sqrt(54), burn=500).max() > 0.15
