"""Has the image stage converged? Rank-normalised split R-hat and bulk/tail ESS, judged.

The rule is Stan's and ArviZ's (Vehtari et al. 2021, "Rank-normalization, folding,
and localization: an improved R-hat"): after the burn-in, every monitored
quantity needs rank-normalised split R-hat below :data:`RHAT_MAX` and bulk- and
tail-ESS of at least :data:`ESS_MIN`, computed over all chains (a single chain
is cut in halves, which are then treated as two chains and split again, so
R-hat is defined for it too). The numbers are ArviZ's
(:func:`mcmcfit.sampling.diagnostics.rank_diagnostics`, vectorised over the
quantities: a verdict on ~170 quantities of 2 x 1000 draws, with the per-step log
densities of 2 x 10,000 steps, takes ~0.2 s, where ArviZ's own per-quantity loop
takes 0.4-1.4 s, longer the slower the chains mix).

Monitored (:func:`monitored_series`): the log posterior, the image and landmark
log likelihoods and the log prior, every sampled parameter column that moves (a
column constant over the kept draws, e.g. a block the schedule never proposes,
is not a random quantity and is left out), and, given the model, the mean
diffuse albedo of each face region (:mod:`mcmcfit.sampling.derived`). A fit that
fails the rule says so: :func:`mcmcfit.jobs.fit_job.fit_into_folder` warns,
``summary.json`` has ``"converged": false`` and the report opens with a banner
naming the worst quantities.

This module imports :mod:`albedo_model.model` and :mod:`mcmcfit.sampling` (chain,
derived, diagnostics, param_vector).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from albedo_model.model import MorphableModel
from mcmcfit.sampling.chain import ChainRecord, stacked_samples
from mcmcfit.sampling.derived import RegionAlbedo, region_albedo_basis, region_albedo_series
from mcmcfit.sampling.diagnostics import series_table
from mcmcfit.sampling.param_vector import ParamLayout

__all__ = ["ESS_MIN", "LOG_DENSITIES", "RHAT_MAX", "convergence", "judge", "monitored_series"]

#: Largest rank-normalised split R-hat of a converged quantity.
RHAT_MAX = 1.01
#: Smallest bulk- and tail-ESS of a converged quantity.
ESS_MIN = 400.0
#: Per-step log densities monitored (``ChainRecord`` attributes).
LOG_DENSITIES = ("log_posterior", "log_lik_img", "log_lik_lm", "log_prior")
_WORST = 5


def monitored_series(records: Sequence[ChainRecord], layout: ParamLayout,
                     model: MorphableModel | RegionAlbedo | None = None, *,
                     burn_fraction: float = 0.0) -> dict[str, np.ndarray]:
    """Return the monitored quantities of one stage's chains, after the burn-in.

    Parameters
    ----------
    records : sequence of ChainRecord
        One stage of each chain (same layout; cut to the shortest).
    layout : ParamLayout
        Columns of the samples.
    model : MorphableModel or RegionAlbedo, optional
        Adds ``albedo_mean.<region>.<r|g|b>``; pass the precomputed
        :func:`~mcmcfit.sampling.derived.region_albedo_basis` when calling often.
    burn_fraction : float in [0, 1)
        Leading fraction of each chain dropped (of the per-step logs and of the
        kept samples separately).

    Returns
    -------
    dict name -> (chains, draws) float64
        Per-step log densities (:data:`LOG_DENSITIES`; the image likelihood only
        for the image stage; none for emcee records), then the parameter columns
        that move and the derived quantities (kept samples).
    """
    recs = [r for r in records if r is not None]
    out: dict[str, np.ndarray] = {}
    if not recs:
        return out
    if all(r.steps > 0 for r in recs):
        steps = min(r.steps for r in recs)
        s0 = int(burn_fraction * steps)
        for name in LOG_DENSITIES:
            if name == "log_lik_img" and recs[0].stage != "image":
                continue
            out[name] = np.stack([getattr(r, name)[s0:steps] for r in recs])
    kept = stacked_samples(recs, layout.size, discard=burn_fraction)  # (chains, draws, d)
    if kept.shape[1] == 0:
        return out
    for j, name in enumerate(layout.names):
        col = kept[:, :, j]
        if np.ptp(col) > 0.0:
            out[name] = col
    if model is not None:
        basis = model if isinstance(model, RegionAlbedo) else region_albedo_basis(model)
        if basis.regions and layout.n_albedo:
            out.update(region_albedo_series(kept, layout, basis))
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
    enough = {k: v for k, v in series.items() if np.ndim(v) == 2 and np.shape(v)[1] >= 8}
    rows = [{"name": k, "rhat": d.rhat, "ess_bulk": d.ess_bulk, "ess_tail": d.ess_tail}
            for k, d in series_table(enough).items()]
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


def convergence(records: Sequence[ChainRecord], *, burn_fraction: float = 0.25,
                model: MorphableModel | RegionAlbedo | None = None) -> dict:
    """Judge the convergence of one stage's chains (see the module notes).

    Parameters
    ----------
    records : sequence of ChainRecord
        The stage of each chain (same layout).
    burn_fraction : float
        Leading fraction of each chain dropped before judging.
    model : MorphableModel or RegionAlbedo, optional
        Monitor the regions' mean diffuse albedo too (see :func:`monitored_series`).

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
    series = (monitored_series(recs, recs[0].layout, model, burn_fraction=burn_fraction)
              if recs and n >= 8 else {})
    out = judge(series)
    return {**out, "chains": len(recs), "draws": int(n - int(burn_fraction * n))}
