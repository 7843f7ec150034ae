"""The Laplace approximation widened from warm-up draws and their gradients (Fisher divergence)."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from proposals.laplace.moves import GaussianApproximation
from proposals.laplace.widening import FISHER_THRESHOLD, widened_by_fisher

D = 140  # about the default fit's number of sampling coordinates
N = 150  # warm-up draws per chain the fit evaluates gradients at


def _approx(rng: np.random.Generator) -> GaussianApproximation:
    a = rng.normal(size=(D, D))
    return GaussianApproximation(rng.normal(size=D), a @ a.T / D + np.eye(D))


def _chain(rng, approx, v=None, ratio=1.0, rho=0.8, gradient_noise=0.0):
    """An AR(1) chain (``rho``: ~9 draws per effective one) on the approximation ``ratio``
    times wider along whitened ``v``; returns its draws and the target's gradients at them,
    plus independent noise of sd ``gradient_noise`` per whitened coordinate (a posterior that
    is not exactly Gaussian)."""
    z = np.empty((N, D))
    z[0] = rng.normal(size=D)
    for i in range(1, N):
        z[i] = rho * z[i - 1] + np.sqrt(1.0 - rho * rho) * rng.normal(size=D)
    s = np.eye(D) if v is None else np.eye(D) + (ratio - 1.0) * np.outer(v, v)
    zt = z @ np.linalg.cholesky(s).T
    lc = approx.chol_cov
    draws = approx.mean + zt @ lc.T
    # d/du log N(u; m, L s L^T) = -L^-T s^-1 z; noise e in whitened units is L^-T e in u
    h = -np.linalg.solve(s, zt.T).T + gradient_noise * rng.normal(size=(N, D))
    return draws, np.linalg.solve(lc.T, h.T).T


def _unit(rng):
    v = rng.normal(size=D)
    return v / np.linalg.norm(v)


@pytest.mark.parametrize("seed", range(4))
def test_an_exactly_gaussian_target_is_recovered_from_few_correlated_draws(seed):
    """For a Gaussian the gradients are exactly linear in the draws: the estimate is exact."""
    rng = np.random.default_rng(seed)
    approx, v = _approx(rng), _unit(rng)
    parts = [_chain(rng, approx, v, 3.5) for _ in range(2)]
    found = widened_by_fisher(approx, [p[0] for p in parts], [p[1] for p in parts])
    assert found.ratios.size == 1
    # only the shrinkage towards the identity (10 pseudo-draws against 298) biases it
    assert found.ratios[0] == pytest.approx(3.5, rel=0.15)
    assert abs(found.directions[:, 0] @ v) > 0.99
    lc, vv = approx.chol_cov, found.directions[:, 0]
    expected = lc @ (np.eye(D) + (found.ratios[0] - 1.0) * np.outer(vv, vv)) @ lc.T
    np.testing.assert_allclose(found.approx.covariance(), expected, rtol=1e-8, atol=1e-10)
    np.testing.assert_array_equal(found.approx.mean, approx.mean)


def test_noisy_gradients_still_find_the_direction_the_draws_alone_miss():
    """Gradient noise (sd 0.5 against a signal of sd ~1) biases the ratio low, not the direction."""
    fisher, draws_only = [], []
    for seed in range(6):
        rng = np.random.default_rng(10 + seed)
        approx, v = _approx(rng), _unit(rng)
        parts = [_chain(rng, approx, v, 3.5, gradient_noise=0.5) for _ in range(2)]
        found = widened_by_fisher(approx, [p[0] for p in parts], [p[1] for p in parts])
        assert found.ratios.size == 1 and 1.8 < found.ratios[0] < 3.5
        fisher.append(abs(found.directions[:, 0] @ v))
        z = np.linalg.solve(approx.chol_cov, np.concatenate(
            [p[0] - p[0].mean(axis=0) for p in parts]).T)
        draws_only.append(abs(np.linalg.eigh(z @ z.T)[1][:, -1] @ v))
    assert min(fisher) > 0.85
    # the same draws' own top direction (what widened_by_draws widens) is mostly noise
    assert np.median(draws_only) < 0.6 < np.median(fisher)


@pytest.mark.parametrize("seed", range(4))
def test_the_approximation_itself_widens_nothing(seed):
    rng = np.random.default_rng(100 + seed)
    approx = _approx(rng)
    parts = [_chain(rng, approx, gradient_noise=0.5) for _ in range(2)]
    parts[1] = (parts[1][0] + 3.0, parts[1][1])  # chains apart: each is centred on its own mean
    found = widened_by_fisher(approx, [p[0] for p in parts], [p[1] for p in parts])
    assert found.ratios.size == 0 and found.approx is approx
    assert found.largest < FISHER_THRESHOLD


def test_bad_draws_or_gradients_are_refused():
    approx = _approx(np.random.default_rng(0))
    x = np.zeros((10, D))
    with pytest.raises(InputError, match="one gradient array per draw array"):
        widened_by_fisher(approx, [x, x], [x])
    with pytest.raises(InputError, match="draws and gradients"):
        widened_by_fisher(approx, [x], [np.zeros((9, D))])
    with pytest.raises(InputError, match="draws and gradients"):
        widened_by_fisher(approx, [x], [np.full((10, D), np.nan)])
    with pytest.raises(InputError, match="threshold"):
        widened_by_fisher(approx, [x], [x], threshold=1.0)
