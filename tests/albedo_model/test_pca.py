"""PCAPart against direct linear-algebra definitions."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from albedo_model.pca import PCAPart, pca_from_data


def random_part(d=30, k=6, seed=0, noise=0.0):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((d, k)))
    return PCAPart(rng.standard_normal(d), q, np.sort(rng.uniform(0.5, 4.0, k))[::-1], noise)


def test_instance_is_mean_plus_scaled_basis():
    p = random_part()
    c = np.random.default_rng(1).standard_normal(p.rank)
    expected = p.mean + p.basis @ (np.sqrt(p.variance) * c)
    np.testing.assert_allclose(p.instance(c), expected, atol=1e-12)
    np.testing.assert_array_equal(p.instance(), p.mean)
    # missing coefficients are zero
    np.testing.assert_allclose(p.instance(c[:2]), p.instance(np.r_[c[:2], np.zeros(p.rank - 2)]))


def test_update_instance_matches_full_instance():
    p = random_part(d=60, k=12)
    rng = np.random.default_rng(2)
    old = rng.standard_normal(12)
    new = old.copy()
    new[4:7] += rng.standard_normal(3)
    inst = p.instance(old)
    np.testing.assert_allclose(p.update_instance(inst, old, new), p.instance(new), atol=1e-12)
    np.testing.assert_allclose(p.update_instance(inst, old, new, slice(4, 7)), p.instance(new), atol=1e-12)


def test_project_inverts_instance_without_noise():
    p = random_part()
    c = np.random.default_rng(3).standard_normal(p.rank)
    np.testing.assert_allclose(p.project(p.instance(c)), c, atol=1e-10)
    # batch projection
    cs = np.random.default_rng(4).standard_normal((5, p.rank))
    np.testing.assert_allclose(p.project(p.mean + cs @ p.scaled_basis.T), cs, atol=1e-10)


def test_project_with_noise_is_ppca_posterior_mean():
    p = random_part(noise=0.3)
    x = np.random.default_rng(5).standard_normal(p.dim)
    # posterior mean of c under x = mean + W c + eps, W = U sqrt(L): (W^T W + s2 I)^-1 W^T (x - mu)
    w = p.basis * np.sqrt(p.variance)
    expected = np.linalg.solve(w.T @ w + 0.3 * np.eye(p.rank), w.T @ (x - p.mean))
    np.testing.assert_allclose(p.project(x), expected, atol=1e-10)


def test_sample_moments():
    p = random_part(d=8, k=3)
    s = p.sample(np.random.default_rng(6), 40000)
    cov = np.cov(s.T)
    expected = (p.basis * p.variance) @ p.basis.T
    np.testing.assert_allclose(s.mean(0), p.mean, atol=0.05)
    np.testing.assert_allclose(cov, expected, atol=0.08)
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), p.marginal_std(), rtol=0.03)


def test_truncate_and_marginal_std():
    p = random_part()
    t = p.truncate(2)
    assert t.rank == 2
    np.testing.assert_array_equal(t.basis, p.basis[:, :2])
    expected = np.sqrt(((p.basis ** 2) * p.variance).sum(1))
    np.testing.assert_allclose(p.marginal_std(), expected)
    with pytest.raises(InputError):
        p.truncate(99)


def test_arrays_are_read_only():
    p = random_part()
    with pytest.raises(ValueError):
        p.mean[0] = 1.0


def test_invalid_parts_raise():
    with pytest.raises(InputError, match="NaN"):
        PCAPart(np.zeros(3), np.full((3, 1), np.nan), np.ones(1))
    with pytest.raises(InputError, match="shape"):
        PCAPart(np.zeros(3), np.zeros((4, 1)), np.ones(1))
    with pytest.raises(InputError):
        random_part().instance(np.full(7, np.inf)[:6])


def test_pca_from_data_fewer_samples_than_dimensions():
    rng = np.random.default_rng(7)
    x = rng.standard_normal((5, 200))
    p = pca_from_data(x)
    assert p.rank == 4  # centring removes one dimension
    np.testing.assert_allclose(p.basis.T @ p.basis, np.eye(4), atol=1e-10)
    # every training sample is reproduced exactly
    np.testing.assert_allclose(p.instance(p.project(x[2])), x[2], atol=1e-9)
    # variances are the non-zero eigenvalues of the sample covariance
    ev = np.sort(np.linalg.eigvalsh(np.cov(x.T)))[::-1][:4]
    np.testing.assert_allclose(p.variance, ev, rtol=1e-8)
