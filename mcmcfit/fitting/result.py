"""The result of a fit: chains, best and mean parameters, acceptance, timings, diagnostics.

This module imports :mod:`albedo_model` (errors, params),
:mod:`mcmcfit.fitting.config` and :mod:`mcmcfit.sampling` (chain, diagnostics,
param_vector).
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import RenderParameter
from mcmcfit.sampling.chain import (
    BestSample, ChainRecord, ChainResult, ProposalStats, stacked_samples,
)
from mcmcfit.sampling.chain_file import write_chains_h5
from mcmcfit.sampling.diagnostics import SeriesDiagnostics
from mcmcfit.fitting.config import FitConfig
from mcmcfit.sampling.param_vector import ParamLayout

__all__ = ["FitResult", "sum_acceptance"]


def sum_acceptance(records: list[ChainRecord | None]) -> dict[str, ProposalStats]:
    """Per-proposal counts summed over records (emcee records have none)."""
    out: dict[str, np.ndarray] = {}
    for r in records:
        if r is None:
            continue
        for name, st in r.acceptance().items():
            out[name] = out.get(name, np.zeros(len(ProposalStats._fields), np.int64)) + np.array(st)
    return {k: ProposalStats(*(int(x) for x in v)) for k, v in sorted(out.items())}


@dataclass
class FitResult:
    """Everything a fit produced.

    Attributes
    ----------
    config : FitConfig
    seed : int
        Root seed; chain i uses ``SeedSequence(seed).spawn(chains)[i]``.
    layout : ParamLayout
        Columns of every sample vector (``layout.names``).
    template : RenderParameter
        The start of the fit (camera for the image size + pose guess, zero
        coefficients); supplies the fields that are never sampled.
    chains : list of ChainResult
        Per chain: ``stage1`` (landmark stage, or None when skipped) and
        ``stage2`` (image stage, or None when ``steps == 0``) ChainRecords.
    best : BestSample
        Highest image likelihood over every stage-2 step of every chain (the
        reference's result; ``fit-best.rps``). Without stage 2: the stage-1
        sample of highest log posterior.
    best_posterior : BestSample
        Highest log posterior (prior + landmarks + image) over the last stage run.
    lm_init : list of RenderParameter
        Per chain, the stage-1 sample of highest log posterior (prior x
        landmarks; ``fitter-lminit.rps``), the start of stage 2 before the light
        solve. The reference takes the best landmark score instead; with
        landmarks alone that is arbitrary along the pitch/yaw vs translation +
        principal-point and distance vs focal-length valleys, which the weak
        priors settle. (Each record still holds ``best_landmarks``.)
    mean_params : RenderParameter or None
        Mean of the pooled stage-2 samples after ``burn_fraction`` (None without stage 2).
    acceptance : dict name -> ProposalStats
        Stage 2, summed over chains (proposed, accepted, rejected by landmarks /
        prior / image).
    acceptance_stage1 : dict name -> ProposalStats
        Stage 1 (MH only).
    timings : dict
        ``setup_s``, ``stage1_s``, ``stage2_s`` (summed over chains), ``total_s``
        (wall), ``stage1_steps_per_s``, ``stage2_steps_per_s``.
    diagnostics : dict
        ``{"stage1": {...}, "stage2": {...}}`` of
        :func:`mcmcfit.sampling.diagnostics.chain_diagnostics` (rank-normalised split
        R-hat, bulk- and tail-ESS of the log densities, every moving parameter and
        the regions' mean albedo).
    landmarks_used, landmarks_unknown : tuple of str
        Target landmarks that took part, and those the model does not have.
    proposal_seconds : dict
        ``{"stage1": {name: s}, "stage2": {name: s}}``: wall time of the steps
        of each proposal, summed over chains (MH stages only).
    convergence : dict
        The image stage's convergence verdict
        (:func:`mcmcfit.sampling.convergence.convergence`; empty without stage 2).
    noise : dict
        The image likelihood's noise model of the kept draws
        (:meth:`mcmcfit.targets.noise_model.NoiseModel.to_dict`: sigma, temperature,
        how it was chosen).
    stopping : dict
        Why the image stage ended (``reason``: "converged", "max steps", "time
        budget"), kept and warm-up steps per chain, and every convergence check
        (kept steps, seconds since the start, max R-hat, min bulk/tail ESS).
    """

    config: FitConfig
    seed: int
    layout: ParamLayout
    template: RenderParameter
    chains: list[ChainResult]
    best: BestSample
    best_posterior: BestSample
    lm_init: list[RenderParameter]
    mean_params: RenderParameter | None
    acceptance: dict[str, ProposalStats]
    acceptance_stage1: dict[str, ProposalStats]
    timings: dict[str, float]
    diagnostics: dict[str, dict[str, SeriesDiagnostics]]
    landmarks_used: tuple[str, ...] = ()
    landmarks_unknown: tuple[str, ...] = ()
    proposal_seconds: dict[str, dict[str, float]] = dataclasses.field(default_factory=dict)
    convergence: dict = dataclasses.field(default_factory=dict)
    noise: dict = dataclasses.field(default_factory=dict)
    stopping: dict = dataclasses.field(default_factory=dict)

    def records(self, stage: int = 2) -> list[ChainRecord]:
        """Return the ChainRecords of one stage (1 or 2), one per chain that ran it."""
        if stage not in (1, 2):
            raise InputError(f"stage must be 1 or 2, got {stage!r}")
        recs = [c.stage1 if stage == 1 else c.stage2 for c in self.chains]
        return [r for r in recs if r is not None]

    def get_chain(self, stage: int = 2, *, flat: bool = False,
                  discard: float = 0.0) -> np.ndarray:
        """Kept samples, emcee-style.

        Parameters
        ----------
        stage : 1 or 2
        flat : bool
            Pool the chains.
        discard : float in [0, 1)
            Leading fraction of each chain's samples dropped.

        Returns
        -------
        (chains, n, d) float64, or (chains n, d) when ``flat``.
        """
        return stacked_samples(self.records(stage), self.layout.size, discard=discard, flat=flat)

    def column(self, name: str, stage: int = 2, *, discard: float = 0.0) -> np.ndarray:
        """(chains, n) samples of one parameter column."""
        return self.get_chain(stage, discard=discard)[..., self.layout.index(name)]

    def save_chain(self, path: str | os.PathLike) -> None:
        """Write ``chain.h5`` (see :func:`mcmcfit.sampling.chain_file.write_chains_h5`), with the config JSON."""
        write_chains_h5(path, self.chains, self.layout, self.template,
                        attrs={"config": self.config.to_json(), "seed": str(self.seed)})

    def summary(self) -> dict:
        """JSON-able overview: best log densities, acceptance, timings, diagnostics."""
        def stats(d: dict[str, ProposalStats]) -> dict:
            return {k: {**v._asdict(), "rate": v.acceptance_rate} for k, v in d.items()}

        def best(b: BestSample) -> dict:
            return {"step": b.step, "log_prior": b.log_prior, "log_lik_lm": b.log_lik_lm,
                    "log_lik_img": b.log_lik_img, "log_posterior": b.log_posterior}

        return {
            "seed": self.seed, "config": self.config.to_dict(),
            "best": best(self.best), "best_posterior": best(self.best_posterior),
            "acceptance": stats(self.acceptance), "acceptance_stage1": stats(self.acceptance_stage1),
            "acceptance_rate": {f"stage{s}": [r.acceptance_rate for r in self.records(s)]
                                for s in (1, 2)},
            "timings": dict(self.timings),
            "diagnostics": {stage: {k: v._asdict() for k, v in d.items()}
                            for stage, d in self.diagnostics.items()},
            "proposal_seconds": {k: dict(v) for k, v in self.proposal_seconds.items()},
            "landmarks_used": list(self.landmarks_used),
            "landmarks_unknown": list(self.landmarks_unknown),
            "noise_model": dict(self.noise),
            "stopping": dict(self.stopping),
        }
