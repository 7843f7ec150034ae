"""The Laplace approximation widened from warm-up draws: found where it should be, nowhere else."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from proposals.laplace.moves import GaussianApproximation
from proposals.laplace.widening import MAX_RATIO, widened_by_draws

D = 60


def _approx(rng: np.random.Generator) -> GaussianApproximation:
    a = rng.normal(size=(D, D))
    precision = a @ a.T / D + np.eye(D)
    return GaussianApproximation(rng.normal(size=D), precision)


def _draws(rng, approx, n, direction=None, ratio=1.0):
    """``n`` iid draws of the approximation, ``ratio`` times wider along whitened ``direction``."""
    z = rng.normal(size=(n, D))
    if direction is not None:
        z += (np.sqrt(ratio) - 1.0) * np.outer(z @ direction, direction)
    return approx.mean + z @ approx.chol_cov.T


@pytest.mark.parametrize("seed", range(4))
def test_a_wider_direction_is_found_and_the_approximation_matches_the_draws(seed):
    rng = np.random.default_rng(seed)
    approx = _approx(rng)
    v = rng.normal(size=D)
    v /= np.linalg.norm(v)
    draws = [_draws(rng, approx, 800, v, 6.0), _draws(rng, approx, 800, v, 6.0) + 0.3]
    found = widened_by_draws(approx, draws, effective_fraction=1.0)
    assert found.ratios.size == 1
    # sampling error of a variance from 1600 draws is ~4 %; the eigenvalue's bias ~d/n
    assert found.ratios[0] == pytest.approx(6.0, rel=0.2)
    assert abs(found.directions[:, 0] @ v) > 0.95
    # the widened approximation's covariance: L (I + (r - 1) v v^T) L^T
    l_chol = approx.chol_cov
    vv = found.directions[:, 0]
    expected = l_chol @ (np.eye(D) + (found.ratios[0] - 1.0) * np.outer(vv, vv)) @ l_chol.T
    np.testing.assert_allclose(found.approx.covariance(), expected, rtol=1e-8, atol=1e-10)
    np.testing.assert_array_equal(found.approx.mean, approx.mean)


@pytest.mark.parametrize("seed", range(6))
def test_draws_of_the_approximation_itself_widen_nothing(seed):
    rng = np.random.default_rng(100 + seed)
    approx = _approx(rng)
    draws = [_draws(rng, approx, 300), _draws(rng, approx, 300) + 5.0]  # chains apart: no spread
    found = widened_by_draws(approx, draws)
    assert found.ratios.size == 0
    assert found.approx is approx
    assert found.largest < found.edge


def test_autocorrelated_draws_of_the_approximation_widen_nothing():
    """An AR(1) chain (rho 0.6: 4 draws per effective one) spreads noise beyond the iid edge."""
    rng = np.random.default_rng(7)
    approx = _approx(rng)
    for _ in range(3):
        z = np.empty((600, D))
        z[0] = rng.normal(size=D)
        for i in range(1, 600):
            z[i] = 0.6 * z[i - 1] + 0.8 * rng.normal(size=D)
        found = widened_by_draws(approx, approx.mean + z @ approx.chol_cov.T)
        assert found.ratios.size == 0


def test_a_far_excursion_is_capped():
    rng = np.random.default_rng(3)
    approx = _approx(rng)
    v = np.eye(D)[0]
    found = widened_by_draws(approx, _draws(rng, approx, 2000, v, 100.0), effective_fraction=1.0)
    assert found.ratios[0] == MAX_RATIO


def test_bad_draws_are_refused():
    approx = _approx(np.random.default_rng(0))
    with pytest.raises(InputError, match="draws"):
        widened_by_draws(approx, np.zeros((10, D + 1)))
    with pytest.raises(InputError, match="draws"):
        widened_by_draws(approx, [np.full((10, D), np.nan)])
    with pytest.raises(InputError, match="effective_fraction"):
        widened_by_draws(approx, np.zeros((10, D)), effective_fraction=0.0)
