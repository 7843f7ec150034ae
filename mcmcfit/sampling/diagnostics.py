"""Convergence diagnostics: integrated autocorrelation time, ESS, split R-hat.

The autocorrelation time is emcee's estimator (``emcee.autocorr.integrated_time``,
Sokal's automatic window with ``c = 5``). On chains shorter than ``tol`` times
the estimate it raises ``AutocorrError``; we then take the estimate computed
anyway (``quiet=True``) and flag it as unreliable instead of failing.

Split R-hat (Gelman et al., BDA3 §11.4): every chain is split in halves, and
``R = sqrt(var_plus / W)`` with W the mean within-half variance and
``var_plus = (n - 1)/n W + B/n`` (B the between-half variance of the means).
Values near 1 mean the chains agree; > 1.1 is the usual alarm.

This module imports only :mod:`mcmcfit.sampling.chain` (for records) from the
project, besides numpy and emcee.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from mcmcfit.sampling.chain import ChainRecord

__all__ = [
    "DEFAULT_COLUMNS",
    "AutocorrEstimate",
    "SeriesDiagnostics",
    "chain_diagnostics",
    "effective_sample_size",
    "integrated_time",
    "series_diagnostics",
    "split_rhat",
]

#: Parameter columns summarised by :func:`chain_diagnostics` when present.
DEFAULT_COLUMNS = ("pose.yaw", "pose.pitch", "camera.focal_length", "shape.0", "albedo.0",
                   "expression.0", "light.0.r")


class AutocorrEstimate(NamedTuple):
    """Integrated autocorrelation time (in steps of the series) and whether it is trusted."""

    tau: float
    reliable: bool


def integrated_time(x: np.ndarray, *, c: float = 5.0, tol: float = 50.0) -> AutocorrEstimate:
    """Estimate emcee's integrated autocorrelation time of a 1-D series.

    Parameters
    ----------
    x : (n,) float array
    c : float
        Window constant of Sokal's automatic window.
    tol : float
        Minimum chain length in units of tau for a reliable estimate.

    Returns
    -------
    AutocorrEstimate
        ``reliable`` is False when emcee found the series too short (the
        estimate is still returned) or the series is constant (tau = 1 then).
    """
    from emcee import autocorr  # imported here: emcee pulls in scipy.stats (~2 s)

    x = np.asarray(x, np.float64).reshape(-1)
    if x.shape[0] < 2 or not np.all(np.isfinite(x)) or np.ptp(x) == 0.0:
        return AutocorrEstimate(1.0, False)
    try:
        return AutocorrEstimate(float(autocorr.integrated_time(x, c=c, tol=tol)[0]), True)
    except autocorr.AutocorrError:
        logger = logging.getLogger("emcee.autocorr")
        level = logger.level
        logger.setLevel(logging.ERROR)
        try:
            tau = float(autocorr.integrated_time(x, c=c, tol=tol, quiet=True)[0])
        finally:
            logger.setLevel(level)
        return AutocorrEstimate(tau, False)


def effective_sample_size(x: np.ndarray, **kwargs) -> tuple[float, bool]:
    """``n / max(tau, 1)`` and the reliability flag of :func:`integrated_time`."""
    x = np.asarray(x, np.float64).reshape(-1)
    est = integrated_time(x, **kwargs)
    return x.shape[0] / max(est.tau, 1.0), est.reliable


def split_rhat(chains: np.ndarray | Sequence[np.ndarray]) -> float:
    """Split R-hat of a scalar over m >= 1 chains.

    Parameters
    ----------
    chains : (m, n) array, or a sequence of m 1-D arrays (truncated to the shortest)

    Returns
    -------
    float
        NaN when fewer than 4 draws per chain or non-finite values; 1.0 when
        every draw is identical.
    """
    seqs = [np.asarray(c, np.float64).reshape(-1) for c in chains]
    n = min(s.shape[0] for s in seqs) if seqs else 0
    half = n // 2
    if half < 2:
        return math.nan
    parts = np.array([p for s in seqs for p in (s[:half], s[half:2 * half])])
    if not np.all(np.isfinite(parts)):
        return math.nan
    means = parts.mean(axis=1)
    w = parts.var(axis=1, ddof=1).mean()
    b = half * means.var(ddof=1)
    if w == 0.0:
        return 1.0 if b == 0.0 else math.inf
    var_plus = (half - 1) / half * w + b / half
    return float(math.sqrt(var_plus / w))


class SeriesDiagnostics(NamedTuple):
    """Diagnostics of one scalar across chains.

    Attributes
    ----------
    tau : tuple of float, per chain (in steps of the series)
    reliable : tuple of bool, per chain
    ess : float, summed over chains
    rhat : float, split R-hat across chains
    """

    tau: tuple
    reliable: tuple
    ess: float
    rhat: float


def series_diagnostics(chains: Sequence[np.ndarray]) -> SeriesDiagnostics:
    """Per-chain tau, total ESS and split R-hat of one scalar series per chain."""
    est = [integrated_time(c) for c in chains]
    ess = sum(np.asarray(c).shape[0] / max(e.tau, 1.0) for c, e in zip(chains, est))
    return SeriesDiagnostics(tuple(e.tau for e in est), tuple(e.reliable for e in est),
                             float(ess), split_rhat(chains))


def chain_diagnostics(records: Sequence[ChainRecord], *, burn_fraction: float = 0.25,
                      columns: Sequence[str] = DEFAULT_COLUMNS) -> dict[str, SeriesDiagnostics]:
    """Diagnostics of one stage over several chains.

    Parameters
    ----------
    records : ChainRecord per chain (same stage and layout)
    burn_fraction : float
        Leading fraction of each series dropped as burn-in.
    columns : parameter names to summarise (those absent from the layout are skipped)

    Returns
    -------
    dict
        ``"log_posterior"`` and ``"log_lik_img"`` (per-step series; ``tau`` in
        steps), then each column of the thinned samples (``tau`` in kept samples).
    """
    if not records:
        return {}
    out = {}

    def tail(a: np.ndarray) -> np.ndarray:
        return a[int(burn_fraction * a.shape[0]):]

    per_step = [r for r in records if r.steps > 0]
    if len(per_step) == len(records):
        out["log_posterior"] = series_diagnostics([tail(r.log_posterior) for r in records])
        if records[0].stage == "image":
            out["log_lik_img"] = series_diagnostics([tail(r.log_lik_img) for r in records])
    names = records[0].layout.names
    for col in columns:
        if col in names and all(r.samples.shape[0] >= 4 for r in records):
            j = names.index(col)
            out[col] = series_diagnostics([tail(r.samples[:, j]) for r in records])
    return out
