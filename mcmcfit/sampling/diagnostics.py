"""Convergence diagnostics: ArviZ's rank-normalised split R-hat and bulk / tail ESS.

The estimators are those of Vehtari et al. (2021, "Rank-normalization, folding,
and localization: an improved R-hat for assessing convergence of MCMC") as
ArviZ implements them: ``arviz.rhat(x, method="rank")`` and
``arviz.ess(x, method="bulk")`` / ``method="tail"`` for a (chains, draws) array.

:func:`rank_diagnostics` computes the three for many quantities at once.
``engine="arviz"`` calls ArviZ once per quantity; the default
``engine="vectorised"`` evaluates the same formulas (split chains, pooled
average ranks back-transformed with Blom's offset 3/8, FFT autocovariances,
Geyer's initial positive and monotone sequences, the 5 % / 95 % quantile
indicators of tail-ESS) on all quantities in one set of array operations:
ArviZ's Python loop over lags takes ~1.4 s for 160 slowly mixing quantities
of 2 x 1000 draws, too slow for a stop rule checked every few hundred steps,
where the vectorised form takes a few tens of milliseconds.
``tests/mcmcfit/sampling/test_diagnostics.py`` checks that both engines agree
to 1e-9 on independent, autocorrelated, drifting, discrete and constant series.

This module imports :mod:`mcmcfit.sampling.chain` (for records) and, in
:func:`chain_diagnostics`, :mod:`mcmcfit.sampling.convergence` (which builds on
this module) from the project, besides numpy, scipy and ArviZ (on first use).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from scipy import fft, special, stats

from mcmcfit.sampling.chain import ChainRecord

__all__ = [
    "RankDiagnostics",
    "SeriesDiagnostics",
    "arviz",
    "chain_diagnostics",
    "effective_sample_size",
    "rank_diagnostics",
]

_TAIL_PROBS = (0.05, 0.95)


def arviz():
    """Return the ``arviz`` module, imported without its refactor announcement."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz as az

    return az


class RankDiagnostics(NamedTuple):
    """Rank-normalised split R-hat, bulk-ESS and tail-ESS of q quantities, (q,) float64 each."""

    rhat: np.ndarray
    ess_bulk: np.ndarray
    ess_tail: np.ndarray


def _split(x: np.ndarray) -> np.ndarray:
    """(q, m, n) -> (q, 2m, n // 2): first and last halves of each chain (ArviZ's split)."""
    half = x.shape[2] // 2
    return np.concatenate([x[:, :, :half], x[:, :, x.shape[2] - half:]], axis=1)


def _z_scale(x: np.ndarray) -> np.ndarray:
    """Return normal scores of the pooled average ranks of each quantity, (q, m, n)."""
    q, m, n = x.shape
    ranks = stats.rankdata(x.reshape(q, m * n), method="average", axis=1)
    return special.ndtri((ranks - 0.375) / (m * n + 0.25)).reshape(x.shape)


def _rhat(x: np.ndarray) -> np.ndarray:
    """Gelman-Rubin R-hat of (q, m, n) chains (m >= 2), (q,)."""
    n = x.shape[2]
    between = n * np.var(x.mean(axis=2), axis=1, ddof=1)
    within = np.var(x, axis=2, ddof=1).mean(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.sqrt((between / within + n - 1) / n)


def _ess(x: np.ndarray) -> np.ndarray:
    """ESS of (q, m, n) chains from Geyer's initial monotone sequence, (q,)."""
    q, m, n = x.shape
    size = m * n
    out = np.full(q, np.nan)
    finite = np.all(np.isfinite(x), axis=(1, 2))
    const = finite & (np.ptp(x, axis=(1, 2)) < np.finfo(float).resolution)
    out[const] = size
    live = finite & ~const
    if not live.any() or n < 4:
        return out
    y = x[live] - x[live].mean(axis=2, keepdims=True)
    nfft = fft.next_fast_len(2 * n, real=True)
    spec = fft.rfft(y, n=nfft, axis=2)
    acov = fft.irfft(spec * np.conj(spec), n=nfft, axis=2)[:, :, :n] / n  # (q', m, n)
    mean_acov = acov.mean(axis=1)  # (q', n)
    mean_var = mean_acov[:, 0] * n / (n - 1.0)
    var_plus = mean_var * (n - 1.0) / n
    if m > 1:
        var_plus = var_plus + np.var(x[live].mean(axis=2), axis=1, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = 1.0 - (mean_var[:, None] - mean_acov) / var_plus[:, None]
    rho[:, 0] = 1.0
    k_max = (n - 3) // 2  # pairs (rho[2k], rho[2k+1]) the initial positive sequence may read
    pairs = rho[:, 0:2 * k_max + 2:2] + rho[:, 1:2 * k_max + 2:2]  # (q', k_max + 1)
    # k_last: the first pair k >= 1 whose sum is <= 0 (the sequence's end), else k_max;
    # 0 when the lag-0/1 pair itself is not positive
    stop = np.concatenate([pairs[:, 1:] <= 0.0, np.ones((pairs.shape[0], 1), bool)], axis=1)
    k_last = np.minimum(np.argmax(stop, axis=1) + 1, k_max)
    k_last = np.where(pairs[:, 0] > 0.0, k_last, 0)
    kept = np.arange(pairs.shape[1])[None, :] < k_last[:, None]
    monotone = np.minimum.accumulate(pairs, axis=1)
    total = np.where(kept, monotone, 0.0).sum(axis=1)
    rows = np.arange(rho.shape[0])
    even = rho[rows, 2 * k_last]
    last_pair = pairs[rows, k_last]
    # the even autocorrelation after the last kept pair adds once, when positive (or kept)
    tail = np.where((even > 0.0) | (last_pair >= 0.0) | (k_last == 0), even, 0.0)
    tau = np.maximum(-1.0 + 2.0 * total + tail, 1.0 / np.log10(size))
    ess = size / tau
    ess[~np.isfinite(rho).all(axis=1)] = np.nan
    out[live] = ess
    return out


def _vectorised(x: np.ndarray) -> RankDiagnostics:
    """All three diagnostics of (q, m, n) draws."""
    q, m, n = x.shape
    nan = np.full(q, np.nan)
    if n < 4:
        return RankDiagnostics(nan, nan.copy(), nan.copy())
    finite = np.all(np.isfinite(x), axis=(1, 2))
    xs = np.where(finite[:, None, None], x, 0.0)
    split = _split(xs)
    z = _z_scale(split)
    rhat = nan.copy()
    if m >= 2:
        folded = np.abs(split - np.median(split.reshape(q, -1), axis=1)[:, None, None])
        rhat = np.fmax(_rhat(z), _rhat(_z_scale(folded)))  # NaN folded (constant): bulk
    ess_bulk = _ess(z)
    quant = np.quantile(xs.reshape(q, -1), _TAIL_PROBS, axis=1)  # (2, q), R's type 7
    ess_tail = np.minimum(*(_ess(_split((xs <= qu[:, None, None]).astype(float)))
                            for qu in quant))
    for a in (rhat, ess_bulk, ess_tail):
        a[~finite] = np.nan
    return RankDiagnostics(rhat, ess_bulk, ess_tail)


def _with_arviz(x: np.ndarray) -> RankDiagnostics:
    """Compute the same by ArviZ, one quantity at a time (the reference)."""
    az = arviz()
    rows = [(float(az.rhat(v, method="rank")), float(az.ess(v, method="bulk")),
             float(az.ess(v, method="tail"))) for v in x]
    a = np.array(rows, np.float64).reshape(-1, 3)
    return RankDiagnostics(a[:, 0], a[:, 1], a[:, 2])


def rank_diagnostics(x: np.ndarray, *, engine: str = "vectorised") -> RankDiagnostics:
    """Rank-normalised split R-hat, bulk-ESS and tail-ESS of one or many quantities.

    Parameters
    ----------
    x : (chains, draws) or (chains, draws, q) float array
        Draws, ArviZ's dimension order. R-hat needs two chains or more (NaN
        otherwise); everything needs four draws or more.
    engine : {"vectorised", "arviz"}
        ``"arviz"`` calls ``arviz.rhat`` / ``arviz.ess`` per quantity; the
        default computes the same numbers for all quantities at once.

    Returns
    -------
    RankDiagnostics
        (q,) arrays (q = 1 for a 2-D ``x``); NaN for quantities with non-finite draws.
    """
    a = np.asarray(x, np.float64)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3:
        raise ValueError(f"draws must be (chains, draws[, q]), got shape {a.shape}")
    a = np.moveaxis(a, 2, 0)
    if engine == "arviz":
        return _with_arviz(a)
    if engine != "vectorised":
        raise ValueError(f"unknown engine {engine!r}")
    return _vectorised(a)


def effective_sample_size(x: np.ndarray) -> tuple[float, bool]:
    """ESS of the mean of one chain (ArviZ's ``ess(method="mean")`` over its split halves).

    Parameters
    ----------
    x : (n,) float array

    Returns
    -------
    (float, bool)
        The ESS, and whether it is trustworthy (finite, and the series at
        least 50 times longer than its autocorrelation time ``n / ess``).
    """
    x = np.asarray(x, np.float64).reshape(-1)
    if x.shape[0] < 4:
        return float("nan"), False
    ess = float(arviz().ess(x[None, :], method="mean"))
    return ess, bool(np.isfinite(ess) and ess >= 50.0)


class SeriesDiagnostics(NamedTuple):
    """Diagnostics of one scalar over all chains.

    Attributes
    ----------
    ess_bulk, ess_tail : float
        Bulk- and tail-ESS, over all chains.
    rhat : float
        Rank-normalised split R-hat (one chain: of its two halves).
    """

    ess_bulk: float
    ess_tail: float
    rhat: float

    @property
    def ess(self) -> float:
        """The bulk-ESS (the name older callers read)."""
        return self.ess_bulk


def chain_diagnostics(records: Sequence[ChainRecord], *, burn_fraction: float = 0.25,
                      columns: Sequence[str] | None = None, model=None
                      ) -> dict[str, SeriesDiagnostics]:
    """Diagnostics of one stage over several chains, for every monitored quantity.

    Parameters
    ----------
    records : ChainRecord per chain (same stage and layout)
    burn_fraction : float
        Leading fraction of each series dropped as burn-in.
    columns : parameter names to keep, optional
        Default: every sampled column that moves (and the log densities).
    model : MorphableModel, optional
        Adds the regions' mean diffuse albedo
        (:func:`mcmcfit.sampling.derived.region_albedo_series`).

    Returns
    -------
    dict
        ``"log_posterior"``, ``"log_lik_img"`` (image stage), ``"log_lik_lm"``,
        ``"log_prior"`` (per-step series), then each parameter column and derived
        quantity (kept samples), as :class:`SeriesDiagnostics`. One chain is cut
        in halves so that R-hat is defined.
    """
    from mcmcfit.sampling.convergence import monitored_series

    recs = [r for r in records if r is not None]
    if not recs:
        return {}
    series = monitored_series(recs, recs[0].layout, model, burn_fraction=burn_fraction)
    if columns is not None:
        keep = set(columns) | {"log_posterior", "log_lik_img", "log_lik_lm", "log_prior"}
        series = {k: v for k, v in series.items() if k in keep or k.startswith("albedo_mean.")}
    return series_table(series)


def series_table(series: dict[str, np.ndarray]) -> dict[str, SeriesDiagnostics]:
    """:class:`SeriesDiagnostics` of (chains, draws) series, grouped by length for speed.

    Parameters
    ----------
    series : mapping name -> (chains, draws) float array
        A single chain is split into its two halves first.

    Returns
    -------
    dict name -> SeriesDiagnostics, in the order of ``series``.
    """
    groups: dict[tuple[int, int], list[str]] = {}
    prepared = {}
    for name, x in series.items():
        x = np.asarray(x, np.float64)
        if x.ndim != 2 or x.shape[1] < 4:
            continue
        if x.shape[0] == 1:
            half = x.shape[1] // 2
            x = np.stack([x[0, :half], x[0, half:2 * half]])
        prepared[name] = x
        groups.setdefault(x.shape, []).append(name)
    out = {}
    for names in groups.values():
        d = rank_diagnostics(np.stack([prepared[k] for k in names], axis=2))
        for i, k in enumerate(names):
            out[k] = SeriesDiagnostics(float(d.ess_bulk[i]), float(d.ess_tail[i]),
                                       float(d.rhat[i]))
    return {k: out[k] for k in prepared}
