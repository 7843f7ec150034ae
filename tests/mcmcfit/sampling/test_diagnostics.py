"""Diagnostics: autocorrelation time / ESS on AR(1) against the analytic value, split R-hat."""

from __future__ import annotations

import numpy as np
import pytest

from mcmcfit.sampling.diagnostics import (
    effective_sample_size,
    integrated_time,
    series_diagnostics,
    split_rhat,
)


def ar1(rng, phi, n, chains=1):
    e = rng.normal(size=(chains, n))
    x = np.empty_like(e)
    x[:, 0] = e[:, 0] / np.sqrt(1 - phi**2)
    for t in range(1, n):
        x[:, t] = phi * x[:, t - 1] + e[:, t]
    return x


@pytest.mark.parametrize("phi", [0.0, 0.5, 0.8])
def test_autocorrelation_time_of_ar1_matches_analytic(phi):
    """tau = (1 + phi) / (1 - phi) for AR(1); ESS = n / tau."""
    rng = np.random.default_rng(0)
    x = ar1(rng, phi, 20000, chains=4)
    analytic = (1 + phi) / (1 - phi)
    taus = [integrated_time(c) for c in x]
    assert all(t.reliable for t in taus)
    assert np.mean([t.tau for t in taus]) == pytest.approx(analytic, rel=0.12)
    ess, ok = effective_sample_size(x[0])
    assert ok and ess == pytest.approx(20000 / analytic, rel=0.25)


def test_short_chain_falls_back_and_is_flagged():
    rng = np.random.default_rng(1)
    x = ar1(rng, 0.95, 200)[0]
    est = integrated_time(x)
    assert not est.reliable and np.isfinite(est.tau) and est.tau > 1
    const = integrated_time(np.ones(50))
    assert const == (1.0, False)


def test_split_rhat_by_hand():
    a = np.array([0.0, 1.0, 2.0, 3.0])
    b = np.array([1.0, 2.0, 3.0, 4.0])
    halves = np.array([[0, 1], [2, 3], [1, 2], [3, 4]], float)
    n = 2
    w = halves.var(axis=1, ddof=1).mean()
    bvar = n * halves.mean(axis=1).var(ddof=1)
    expected = np.sqrt(((n - 1) / n * w + bvar / n) / w)
    assert split_rhat([a, b]) == pytest.approx(expected)


def test_rhat_near_one_for_identical_chains_and_large_for_shifted():
    rng = np.random.default_rng(2)
    same = ar1(rng, 0.5, 2000, chains=4)
    assert split_rhat(same) == pytest.approx(1.0, abs=0.02)
    shifted = same.copy()
    shifted[0] += 2.0  # two stationary sds
    assert split_rhat(shifted) > 1.1
    drifting = same + np.linspace(0, 3, 2000)  # non-stationary within chains: split catches it
    assert split_rhat(drifting) > 1.1
    d = series_diagnostics(list(same))
    assert len(d.tau) == 4 and d.ess > 1000 and d.rhat < 1.02
