"""Posterior predictive albedo intervals: the model's residual variance added to the coefficients'.

Toy truth = a span part drawn from the coefficients' (known) posterior + independent
out-of-span noise of known per-row variance. The predictive intervals must cover at
the nominal rate; the coefficient-only ones undercover, as the analytic rate says.
"""

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.stats import norm

from albedo_model.pca import PCAPart
from mcmcfit.outputs.posterior import albedo_posterior


def _part(seed, n=300, k=6):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((3 * n, k)))
    residual = rng.uniform(0.5, 2.0, 3 * n) * 1e-4          # out-of-span sd ~ 0.01
    return PCAPart(rng.uniform(0.1, 0.6, 3 * n), q, np.linspace(0.04, 0.01, k),
                   residual_variance=residual)


def _case(seed, n_samples=500):
    """Part, posterior samples of c, the true albedo, the coefficient-only variance per row."""
    part = _part(seed)
    rng = np.random.default_rng(100 + seed)
    m = rng.standard_normal(part.rank)
    s = np.full(part.rank, 0.12)                              # posterior sd of the coefficients
    c_true = m + s * rng.standard_normal(part.rank)
    truth = part.instance(c_true) + rng.standard_normal(part.dim) * np.sqrt(
        part.residual_variance)
    samples = m + s * rng.standard_normal((n_samples, part.rank))
    var_c = (part.scaled_basis**2) @ s**2
    return part, samples, truth.reshape(-1, 3), var_c


def _cover(lo, hi, truth):
    return float(np.mean((truth >= lo) & (truth <= hi)))


def test_predictive_intervals_cover_at_the_nominal_rate_coefficient_only_undercover():
    pred, coef, expected_coef = [], [], []
    for seed in range(12):
        part, samples, truth, var_c = _case(seed)
        post = albedo_posterior(part, samples, rng=np.random.default_rng(seed))
        assert post.predictive
        pred.append(_cover(post.lo, post.hi, truth))
        only = post.coefficient_only()
        coef.append(_cover(only.lo, only.hi, truth))
        z = norm.ppf(0.95) * np.sqrt(var_c / (var_c + part.residual_variance))
        expected_coef.append(np.mean(2 * norm.cdf(z) - 1))
    # 12 seeds x 900 rows; rows of one seed share the span draw, so allow +-2.5 points
    assert abs(np.mean(pred) - 0.90) < 0.025, pred
    assert min(pred) > 0.84
    assert abs(np.mean(coef) - np.mean(expected_coef)) < 0.03, (coef, expected_coef)
    assert np.mean(coef) < 0.75                              # the negative control undercovers


def test_predictive_std_is_exact_and_the_coefficient_part_is_kept():
    part, samples, _, _ = _case(0)
    post = albedo_posterior(part, samples)
    only = albedo_posterior(part, samples, predictive=False)
    assert not only.predictive and only.coef_std is None
    c = np.cov(samples, rowvar=False, ddof=0)
    w = part.scaled_basis
    var_c = np.einsum("ij,ij->i", w @ c, w)
    np.testing.assert_allclose(post.std.ravel() ** 2, var_c + part.residual_variance, rtol=1e-5)
    np.testing.assert_allclose(post.coef_std, only.std, rtol=1e-6)
    np.testing.assert_array_equal(post.coef_lo, only.lo)
    np.testing.assert_array_equal(post.coef_hi, only.hi)
    np.testing.assert_array_equal(post.mean, only.mean)
    np.testing.assert_allclose(post.residual_std.ravel() ** 2, part.residual_variance, rtol=1e-6)
    # reproducible by default, and the coefficient_only() view is the plain summary
    again = albedo_posterior(part, samples)
    np.testing.assert_array_equal(post.lo, again.lo)
    np.testing.assert_array_equal(post.coefficient_only().std, only.std)


def test_monte_carlo_bounds_match_the_exact_mixture_quantiles():
    part = _part(3, n=20)
    rng = np.random.default_rng(4)
    samples = rng.normal(0.0, 0.3, (50, part.rank))          # 50 samples x 40 repeats
    post = albedo_posterior(part, samples, block_rows=7, rng=rng, min_draws=2000)
    x = part.mean + samples @ part.scaled_basis.T            # (S, d) coefficient-only draws
    sd = np.sqrt(part.residual_variance)
    errs = []
    for i in range(part.dim):
        cdf = lambda t, i=i: norm.cdf((t - x[:, i]) / sd[i]).mean()  # noqa: E731
        a, b = x[:, i].min() - 10 * sd[i], x[:, i].max() + 10 * sd[i]
        exact = [brentq(lambda t, p=p: cdf(t) - p, a, b) for p in (0.05, 0.95)]
        got = (post.lo.ravel()[i], post.hi.ravel()[i])
        errs += [abs(g - e) / post.std.ravel()[i] for g, e in zip(got, exact)]
    errs = np.array(errs)
    # Monte Carlo error of a 5 % quantile at 2,000 draws: ~0.05 predictive sd
    assert errs.mean() < 0.07 and errs.max() < 0.3


def test_without_residual_the_summaries_are_coefficient_only():
    part = _part(1).with_residual_variance(None)
    post = albedo_posterior(part, np.random.default_rng(0).standard_normal((200, part.rank)))
    assert not post.predictive and post.residual_std is None
    only = post.coefficient_only()
    np.testing.assert_array_equal(only.lo, post.lo)


@pytest.mark.parametrize("n_samples", [1, 3])
def test_few_samples_give_the_residual_spread(n_samples):
    part = _part(2, n=50)
    samples = np.zeros((n_samples, part.rank))
    post = albedo_posterior(part, samples)
    # one point mass: the predictive is N(mean, r); its 90 % half-width is 1.645 sd
    half = (post.hi - post.lo).ravel() / 2
    ratio = half / np.sqrt(part.residual_variance)
    assert abs(np.median(ratio) - norm.ppf(0.95)) < 0.05
    np.testing.assert_allclose(post.coef_lo, post.coef_hi)


def test_summaries_do_not_depend_on_the_thread_count():
    """Blocks draw from their own streams: 1 and 3 threads give the same bounds, bit for bit."""
    part, samples, _, _ = _case(4, n_samples=300)
    small_blocks = {"block_rows": 64, "min_draws": 1000}
    one = albedo_posterior(part, samples, rng=np.random.default_rng(7), threads=1, **small_blocks)
    three = albedo_posterior(part, samples, rng=np.random.default_rng(7), threads=3,
                             **small_blocks)
    for name in ("mean", "std", "lo", "hi", "coef_lo", "coef_hi"):
        np.testing.assert_array_equal(getattr(one, name), getattr(three, name))
    a = albedo_posterior(part, samples, predictive=False, threads=1, block_rows=64)
    b = albedo_posterior(part, samples, predictive=False, threads=3, block_rows=64)
    np.testing.assert_array_equal(a.lo, b.lo)
    np.testing.assert_array_equal(a.hi, one.coef_hi)
