"""Has the image stage converged? ArviZ's rank-normalised split R-hat and bulk/tail ESS, judged.

The rule is Stan's and ArviZ's (Vehtari et al. 2021, "Rank-normalization, folding,
and localization: an improved R-hat"): after the burn-in, every monitored
quantity needs rank-normalised split R-hat below :data:`RHAT_MAX` and bulk- and
tail-ESS of at least :data:`ESS_MIN`, computed over all chains (a single chain
is cut in halves, which ArviZ then treats as two chains and splits again, so
R-hat is defined for it too). Monitored: the log
posterior, the image log likelihood and every sampled parameter column that
moves (a column constant over the kept draws, e.g. a block the schedule never
proposes, is not a random quantity and is left out). A fit that fails the rule
says so: :func:`mcmcfit.jobs.fit_job.fit_into_folder` warns, ``summary.json``
has ``"converged": false`` and the report opens with a banner naming the worst
quantities.

This module imports :mod:`mcmcfit.sampling.chain` (and ArviZ when it runs).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

from mcmcfit.sampling.chain import ChainRecord, stacked_samples

__all__ = ["ESS_MIN", "RHAT_MAX", "convergence", "judge"]

#: Largest rank-normalised split R-hat of a converged quantity.
RHAT_MAX = 1.01
#: Smallest bulk- and tail-ESS of a converged quantity.
ESS_MIN = 400.0
_WORST = 5


def _arviz():
    with warnings.catch_warnings():  # ArviZ announces its refactor on import
        warnings.simplefilter("ignore", FutureWarning)
        import arviz

    return arviz


def _series(records: Sequence[ChainRecord], burn_fraction: float) -> dict[str, np.ndarray]:
    """(chains, draws) arrays of the monitored quantities after the burn-in."""
    out: dict[str, np.ndarray] = {}
    if records[0].steps > 0:
        steps = min(r.steps for r in records)
        s0 = int(burn_fraction * steps)
        out["log_posterior"] = np.stack([r.log_posterior[s0:steps] for r in records])
        out["log_lik_img"] = np.stack([r.log_lik_img[s0:steps] for r in records])
    layout = records[0].layout
    kept = stacked_samples(records, layout.size, discard=burn_fraction)  # (chains, draws, d)
    for j, name in enumerate(layout.names):
        col = kept[:, :, j]
        if col.size and np.ptp(col) > 0.0:
            out[name] = col
    return out


def judge(series: dict[str, np.ndarray]) -> dict:
    """Apply the rule to monitored quantities given as (chains, draws) arrays.

    Parameters
    ----------
    series : mapping name -> (chains, draws) float array
        Post-burn-in draws of each quantity (quantities with fewer than 8 draws are skipped).

    Returns
    -------
    dict
        As :func:`convergence` (without ``chains`` and ``draws``).
    """
    rule = (f"rank-normalised split R-hat < {RHAT_MAX} and bulk- and tail-ESS >= {ESS_MIN:g} "
            "on every monitored quantity (ArviZ), after the burn-in")
    rows = []
    az = _arviz() if series else None
    for name, x in series.items():
        x = np.asarray(x, np.float64)
        if x.ndim != 2 or x.shape[1] < 8:
            continue
        if x.shape[0] == 1:  # one chain: its two halves (ArviZ wants two chains or more)
            half = x.shape[1] // 2
            x = np.stack([x[0, :half], x[0, half:2 * half]])
        rows.append({"name": name, "rhat": float(az.rhat(x, method="rank")),
                     "ess_bulk": float(az.ess(x, method="bulk")),
                     "ess_tail": float(az.ess(x, method="tail"))})
    if not rows:
        return {"converged": False, "rule": rule, "n_quantities": 0, "max_rhat": math.nan,
                "min_ess_bulk": math.nan, "min_ess_tail": math.nan, "worst": []}

    def badness(row) -> float:  # > 1 fails; the largest of the three criteria
        rhat = row["rhat"] if math.isfinite(row["rhat"]) else math.inf
        return max((rhat - 1.0) / (RHAT_MAX - 1.0), ESS_MIN / max(row["ess_bulk"], 1e-9),
                   ESS_MIN / max(row["ess_tail"], 1e-9))

    rows.sort(key=badness, reverse=True)
    return {"converged": all(badness(r) <= 1.0 for r in rows), "rule": rule,
            "n_quantities": len(rows),
            "max_rhat": float(np.nanmax([r["rhat"] for r in rows])),
            "min_ess_bulk": float(np.nanmin([r["ess_bulk"] for r in rows])),
            "min_ess_tail": float(np.nanmin([r["ess_tail"] for r in rows])),
            "worst": rows[:_WORST]}


def convergence(records: Sequence[ChainRecord], *, burn_fraction: float = 0.25) -> dict:
    """Judge the convergence of one stage's chains (see the module notes).

    Parameters
    ----------
    records : sequence of ChainRecord
        The stage of each chain (same layout).
    burn_fraction : float
        Leading fraction of each chain dropped before judging.

    Returns
    -------
    dict
        ``converged`` (bool), ``rule`` (text), ``chains``, ``draws`` (kept samples per
        chain after the burn-in), ``n_quantities``, ``max_rhat``, ``min_ess_bulk``,
        ``min_ess_tail``, and ``worst``: up to five quantities failing the rule (or
        closest to failing), each ``{"name", "rhat", "ess_bulk", "ess_tail"}``. With
        fewer than 8 kept draws per chain nothing can be judged: ``converged`` is False.
    """
    recs = [r for r in records if r is not None]
    n = min((r.samples.shape[0] for r in recs), default=0)
    series = _series(recs, burn_fraction) if recs and n >= 8 else {}
    out = judge(series)
    return {**out, "chains": len(recs), "draws": int(n - int(burn_fraction * n))}
