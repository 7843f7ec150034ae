"""Posterior albedo summaries against brute force over sample instances."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from albedo_model.pca import PCAPart
from mcmcfit.outputs.posterior import albedo_posterior


def part(n=40, k=5, seed=0):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((3 * n, k)))
    return PCAPart(rng.uniform(0.1, 0.6, 3 * n), q, np.linspace(0.04, 0.01, k))


def test_matches_brute_force_over_instances():
    p = part()
    rng = np.random.default_rng(1)
    samples = rng.normal([0.5, -1, 0.2], [0.3, 0.1, 0.5], size=(2000, 3))
    post = albedo_posterior(p, samples, level=0.9, block_rows=17)
    inst = np.stack([p.instance(c) for c in samples]).reshape(len(samples), -1, 3)
    np.testing.assert_allclose(post.mean, inst.mean(0), atol=1e-6)
    np.testing.assert_allclose(post.std, inst.std(0), atol=1e-6)
    np.testing.assert_allclose(post.lo, np.quantile(inst, 0.05, axis=0), atol=1e-6)
    np.testing.assert_allclose(post.hi, np.quantile(inst, 0.95, axis=0), atol=1e-6)
    assert post.mean.shape == (40, 3) and post.mean.dtype == np.float32


@pytest.mark.parametrize("seed", range(3))
def test_bounds_from_thinned_draws_match_the_analytic_quantiles(seed):
    """20,000 Gaussian draws, bounds read from 4,000 of them: within 0.1 sd of mean -+ 1.645 sd."""
    p = part(n=60, k=4, seed=seed)
    rng = np.random.default_rng(10 + seed)
    samples = rng.normal(0.3, 0.7, size=(20000, 4))
    post = albedo_posterior(p, samples, level=0.9)
    w = p.scaled_basis
    mean = (p.mean + w @ np.full(4, 0.3)).reshape(-1, 3)
    sd = (0.7 * np.sqrt((w * w).sum(1))).reshape(-1, 3)
    np.testing.assert_allclose(post.std, sd, rtol=0.03)  # every draw: exact up to sampling
    z = 1.6448536
    assert np.max(np.abs(post.lo - (mean - z * sd)) / sd) < 0.1
    assert np.max(np.abs(post.hi - (mean + z * sd)) / sd) < 0.1
    # reading all 20,000 draws gives the same bounds to Monte Carlo error
    full = albedo_posterior(p, samples, level=0.9, max_draws=20000)
    assert np.max(np.abs(full.lo - post.lo) / sd) < 0.1


def test_single_sample_has_zero_width():
    p = part()
    post = albedo_posterior(p, np.ones((1, 5)))
    np.testing.assert_allclose(post.std, 0.0)
    np.testing.assert_allclose(post.lo, post.hi)


def test_gaussian_coverage():
    # samples from the prior: 90 % intervals cover 90 % of fresh prior draws per vertex
    p = part(n=200, k=4)
    rng = np.random.default_rng(2)
    post = albedo_posterior(p, rng.standard_normal((4000, 4)))
    truth = p.instance(rng.standard_normal(4)).reshape(-1, 3)
    cover = ((truth >= post.lo) & (truth <= post.hi)).mean()
    assert 0.6 < cover <= 1.0
    np.testing.assert_allclose(post.std.ravel(), p.marginal_std(), rtol=0.05)


def test_bad_input():
    with pytest.raises(InputError):
        albedo_posterior(part(), np.zeros((3, 9)))
    with pytest.raises(InputError):
        albedo_posterior(part(), np.zeros(5))
    with pytest.raises(InputError):
        albedo_posterior(part(), np.zeros((3, 5)), level=1.5)
