"""Diagnostics: the vectorised rank diagnostics equal ArviZ's; ESS and R-hat against known series."""

from __future__ import annotations

import time

import numpy as np
import pytest

from mcmcfit.sampling.diagnostics import (
    effective_sample_size,
    rank_diagnostics,
    series_table,
)


def ar1(rng, phi, n, chains=1, q=None):
    shape = (chains, n) if q is None else (chains, n, q)
    e = rng.normal(size=shape)
    x = np.empty_like(e)
    x[:, 0] = e[:, 0] / np.sqrt(max(1 - phi**2, 1e-12))
    for t in range(1, n):
        x[:, t] = phi * x[:, t - 1] + e[:, t]
    return x


def _cases(rng):
    drift = rng.normal(size=(2, 600, 6)) + np.linspace(0, 3, 600)[None, :, None]
    const = np.ones((2, 100, 3))
    const[:, :, 1] = 0.0
    const[:, 50:, 2] = 2.0  # constant within each half
    rejected = np.repeat(rng.normal(size=(2, 150, 4)), 4, axis=1)  # MH-like repeats: ties
    return {
        "iid": rng.normal(size=(2, 1000, 8)),
        "ar0.9": ar1(rng, 0.9, 1000, 2, 8),
        "ar0.99 three chains, odd length": ar1(rng, 0.99, 501, 3, 8),
        "random walk": ar1(rng, 1.0, 800, 2, 8),
        "antithetic": ar1(rng, -0.7, 300, 2, 8),
        "drift": drift,
        "discrete": rng.integers(0, 3, size=(2, 300, 6)).astype(float),
        "ties": rejected,
        "short": rng.normal(size=(2, 9, 5)),
        "one chain": ar1(rng, 0.5, 400, 1, 5),
        "constant": const,
    }


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("seed", range(3))
def test_vectorised_engine_equals_arviz(seed):
    """Same numbers as arviz.rhat(method="rank") / arviz.ess(method="bulk"/"tail"), to 1e-9.

    Where every chain half is constant at different values both report ~1e16 (the
    rounding residue of a zero within-chain variance), compared as infinite.
    """
    for name, x in _cases(np.random.default_rng(seed)).items():
        ref = rank_diagnostics(x, engine="arviz")
        got = rank_diagnostics(x)
        for field, a, b in zip(ref._fields, ref, got):
            a, b = (np.where(v > 1e10, np.inf, v) for v in (a, b))  # a zero variance's residue
            assert np.array_equal(np.isnan(a), np.isnan(b)), (name, field, a, b)
            ok = ~np.isnan(a)
            np.testing.assert_allclose(b[ok], a[ok], rtol=1e-9, atol=1e-12, err_msg=f"{name} {field}")


def test_nan_draws_give_nan_and_leave_the_others_alone():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(2, 200, 3))
    x[1, 7, 1] = np.nan
    d = rank_diagnostics(x)
    assert np.isnan(d.rhat[1]) and np.isnan(d.ess_bulk[1]) and np.isnan(d.ess_tail[1])
    ref = rank_diagnostics(x[:, :, [0, 2]])
    np.testing.assert_allclose(d.ess_bulk[[0, 2]], ref.ess_bulk)


@pytest.mark.parametrize("phi", [0.0, 0.5, 0.8])
def test_ess_of_ar1_matches_analytic(phi):
    """ESS = n (1 - phi) / (1 + phi) for AR(1), over five seeds, within 15 %."""
    analytic = 4 * 4000 * (1 - phi) / (1 + phi)
    ess = [rank_diagnostics(ar1(np.random.default_rng(s), phi, 4000, chains=4)).ess_bulk[0]
           for s in range(5)]
    assert np.mean(ess) == pytest.approx(analytic, rel=0.15)
    single = [effective_sample_size(ar1(np.random.default_rng(s), phi, 20000)[0])[0]
              for s in range(5)]
    assert np.mean(single) == pytest.approx(20000 * (1 - phi) / (1 + phi), rel=0.15)


def test_rhat_near_one_for_agreeing_chains_and_large_for_shifted_or_drifting():
    for seed in range(3):
        same = ar1(np.random.default_rng(seed), 0.5, 2000, chains=4)
        assert rank_diagnostics(same).rhat[0] == pytest.approx(1.0, abs=0.01)
        shifted = same.copy()
        shifted[0] += 2.0  # two stationary sds
        assert rank_diagnostics(shifted).rhat[0] > 1.1
        drifting = same + np.linspace(0, 3, 2000)  # non-stationary within chains: split sees it
        assert rank_diagnostics(drifting).rhat[0] > 1.1
        wide = same.copy()
        wide[0] *= 4.0  # same location, other scale: only the folded R-hat catches it
        assert rank_diagnostics(wide).rhat[0] > 1.05


def test_series_table_splits_one_chain_and_groups_lengths():
    rng = np.random.default_rng(4)
    t = series_table({"a": rng.normal(size=(1, 1000)), "b": rng.normal(size=(2, 300)),
                      "too_short": np.zeros((2, 3))})
    assert list(t) == ["a", "b"]
    assert np.isfinite(t["a"].rhat) and t["a"].rhat < 1.02
    assert t["a"].ess == t["a"].ess_bulk > 500


def test_many_quantities_are_fast():
    """~160 slowly mixing quantities of 2 x 1000 draws: well under the stop rule's 0.5 s."""
    x = ar1(np.random.default_rng(5), 0.99, 1000, chains=2, q=160)
    rank_diagnostics(x[:, :, :4])
    t0 = time.perf_counter()
    rank_diagnostics(x)
    assert time.perf_counter() - t0 < 0.5
