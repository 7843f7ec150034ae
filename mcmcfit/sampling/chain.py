"""Recording chains: per-step logs, thinned samples, best samples.

A :class:`ChainRecorder` is the sampler's callback; it fills a
:class:`ChainRecord`:

* per step (after the step): ``log_prior``, ``log_lik_lm``, ``log_lik_img``,
  the proposal (index into ``proposal_names``), ``accepted`` and
  ``rejected_by`` (0 accepted, 1 landmarks, 2 prior, 3 image, 4 joint test, 5 identity move:
  :data:`mcmcfit.sampling.kernel.REJECTION_STAGES`);
* every ``thin``-th step: the parameter vector
  (:class:`~mcmcfit.sampling.param_vector.ParamLayout`);
* the best states by image likelihood (the reference's result), by landmark
  likelihood (the reference's ``lminit``) and by log posterior, over every
  step including the initial state (step -1).

The chain file (``chain.h5``) is :mod:`mcmcfit.sampling.chain_file`.

This module imports :mod:`albedo_model.params`, :mod:`mcmcfit.sampling.kernel` and
:mod:`mcmcfit.sampling.param_vector`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from albedo_model.params import RenderParameter
from mcmcfit.sampling.kernel import REJECTION_STAGES, ChainState, StepInfo
from mcmcfit.sampling.param_vector import ParamLayout

__all__ = [
    "BestSample",
    "ChainRecord",
    "ChainRecorder",
    "ChainResult",
    "ProposalStats",
    "stacked_samples",
]


class BestSample(NamedTuple):
    """A remembered state: parameters, the step after which it was current, its log densities."""

    params: RenderParameter
    step: int
    log_prior: float
    log_lik_lm: float
    log_lik_img: float

    @property
    def log_posterior(self) -> float:
        """Unnormalised log posterior: log prior plus both log likelihoods."""
        return self.log_prior + self.log_lik_lm + self.log_lik_img


class ProposalStats(NamedTuple):
    """Counts for one proposal: proposed, accepted, rejected by each stage, identity moves.

    ``identity`` counts the steps whose move changed nothing (the proposal had
    nothing to move); they are neither accepted nor rejected.
    """

    proposed: int
    accepted: int
    rejected_landmarks: int
    rejected_prior: int
    rejected_image: int
    rejected_joint: int = 0
    identity: int = 0

    @property
    def acceptance_rate(self) -> float:
        """Accepted over proposed moves that moved (identity moves left out); NaN for none."""
        moved = self.proposed - self.identity
        return self.accepted / moved if moved else float("nan")


def stacked_samples(records: Sequence[ChainRecord], size: int, *, discard: float = 0.0,
                    flat: bool = False, before_step: int | None = None) -> np.ndarray:
    """Kept samples of several chains after a burn-in, emcee's ``get_chain`` style.

    Parameters
    ----------
    records : sequence of ChainRecord
        One stage of each chain.
    size : int
        Columns of a sample (the layout's size), for the empty case.
    discard : float in [0, 1)
        Leading fraction of each chain's samples dropped (of the shortest chain's count).
    flat : bool
        Pool the chains.
    before_step : int, optional
        Only the samples recorded before this step of the stage (the chains as
        they were at a checkpoint); the burn-in is then a fraction of those.

    Returns
    -------
    (chains, n, size) float64, or (chains n, size) when ``flat``; chains are cut
    to the shortest one.
    """
    if not records:
        return np.zeros((0, size)) if flat else np.zeros((0, 0, size))
    kept = [r.samples if before_step is None else r.samples[r.sample_step < before_step]
            for r in records]
    n = min(k.shape[0] for k in kept)
    start = int(discard * n)
    arr = np.stack([k[start:n] for k in kept])
    return arr.reshape(-1, size) if flat else arr


def _best(state: ChainState, step: int) -> BestSample:
    return BestSample(state.params, step, state.log_prior, state.log_lik_lm, state.log_lik_img)


@dataclass
class ChainRecord:
    """One stage of one chain.

    Attributes
    ----------
    stage : {"landmarks", "image"}
    sampler : {"mh", "emcee"}
    thin : int
    steps : int
        Steps run (per-step arrays have this length; 0 for emcee).
    sample_step : (n,) int64
        Step index after which each kept sample was current.
    samples : (n, d) float64
        Parameter vectors (``layout``).
    log_prior, log_lik_lm, log_lik_img : (steps,) float64
        Of the state after each step (for emcee: of each kept sample, (n,)).
    proposal : (steps,) int32, index into ``proposal_names``
    accepted : (steps,) bool
    rejected_by : (steps,) int8
    best_image, best_landmarks, best_posterior : BestSample
    seconds : float
        Wall time of the stage.
    extra : dict
        Sampler-specific extras (emcee: walkers, acceptance fraction).
    step_seconds : (steps,) float32
        Wall time of each step (proposal, evaluation and recording); empty when
        not measured (emcee, older files).
    """

    stage: str
    sampler: str
    thin: int
    steps: int
    layout: ParamLayout
    sample_step: np.ndarray
    samples: np.ndarray
    log_prior: np.ndarray
    log_lik_lm: np.ndarray
    log_lik_img: np.ndarray
    proposal: np.ndarray
    proposal_names: tuple[str, ...]
    accepted: np.ndarray
    rejected_by: np.ndarray
    best_image: BestSample
    best_landmarks: BestSample
    best_posterior: BestSample
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)
    step_seconds: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))

    @property
    def log_posterior(self) -> np.ndarray:
        """Per-step log posterior ``log p + l_lm + l_img``."""
        return self.log_prior + self.log_lik_lm + self.log_lik_img

    @property
    def acceptance_rate(self) -> float:
        """Fraction of accepted steps (emcee: the mean acceptance fraction)."""
        if self.steps == 0:
            return float(self.extra.get("acceptance_fraction", float("nan")))
        return float(np.mean(self.accepted))

    def acceptance(self) -> dict[str, ProposalStats]:
        """Per-proposal counts over every step, by proposal name."""
        out = {}
        for i, name in enumerate(self.proposal_names):
            sel = self.proposal == i
            rb = self.rejected_by[sel]
            counts = np.bincount(rb.astype(np.int64), minlength=len(REJECTION_STAGES))
            out[name] = ProposalStats(int(sel.sum()), *(int(c) for c in counts[:6]))
        return out

    def time_by_proposal(self) -> dict[str, float]:
        """Seconds spent in the steps of each proposal, by name (empty when not measured)."""
        if self.step_seconds.shape[0] != self.steps or self.steps == 0:
            return {}
        t = np.bincount(self.proposal, weights=self.step_seconds.astype(np.float64),
                        minlength=len(self.proposal_names))
        return {name: float(t[i]) for i, name in enumerate(self.proposal_names)}

    def sample_log_posterior(self) -> np.ndarray:
        """Log posterior of each kept sample, (n,)."""
        if self.steps == 0:
            return self.log_posterior
        return self.log_posterior[self.sample_step]


class ChainRecorder:
    """Sampler callback filling a :class:`ChainRecord` (preallocated arrays).

    Parameters
    ----------
    layout : ParamLayout
    n_steps : int
    thin : int
        Keep the state after every ``thin``-th step (steps thin-1, 2 thin-1, ...).
    initial : ChainState
        The state before the first step (a candidate for the best samples).
    stage : {"landmarks", "image"}
    """

    def __init__(self, layout: ParamLayout, n_steps: int, thin: int, initial: ChainState, *,
                 stage: str):
        self.layout, self.n, self.thin, self.stage = layout, int(n_steps), max(1, int(thin)), stage
        n_kept = self.n // self.thin
        self._samples = np.empty((n_kept, layout.size))
        self._sample_step = np.empty(n_kept, np.int64)
        self._k = 0
        self._lp, self._lm, self._li = (np.empty(self.n) for _ in range(3))
        self._prop = np.empty(self.n, np.int32)
        self._acc = np.empty(self.n, bool)
        self._rej = np.empty(self.n, np.int8)
        self._names: dict[str, int] = {}
        self.best_image = self.best_landmarks = self.best_posterior = _best(initial, -1)
        self.steps_done = 0
        self._dt = np.zeros(self.n, np.float32)
        self._last = time.perf_counter()

    def __call__(self, i: int, state: ChainState, info: StepInfo) -> None:
        """Record step ``i`` (0-based) with the state after it."""
        now = time.perf_counter()
        self._dt[i], self._last = now - self._last, now
        self._lp[i], self._lm[i], self._li[i] = state.log_prior, state.log_lik_lm, state.log_lik_img
        idx = self._names.setdefault(info.proposal, len(self._names))
        self._prop[i], self._acc[i], self._rej[i] = idx, info.accepted, info.rejected_by
        if info.accepted:
            if state.log_lik_img > self.best_image.log_lik_img:
                self.best_image = _best(state, i)
            if state.log_lik_lm > self.best_landmarks.log_lik_lm:
                self.best_landmarks = _best(state, i)
            if state.log_posterior > self.best_posterior.log_posterior:
                self.best_posterior = _best(state, i)
        if (i + 1) % self.thin == 0 and self._k < self._samples.shape[0]:
            self._samples[self._k] = self.layout.to_vector(state.params)
            self._sample_step[self._k] = i
            self._k += 1
        self.steps_done = i + 1

    def proposals_since(self, first: int) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
        """Return ``(proposal index, accepted, proposal names)`` of the steps from ``first`` on."""
        n = self.steps_done
        return self._prop[first:n].copy(), self._acc[first:n].copy(), tuple(self._names)

    def extend(self, n_more: int) -> None:
        """Make room for ``n_more`` further steps (a chain run in rounds until it converges)."""
        n_more = int(n_more)
        if n_more <= 0:
            return
        self.n += n_more

        def grow(a: np.ndarray, n: int) -> np.ndarray:
            out = np.zeros((n,) + a.shape[1:], a.dtype)
            out[: a.shape[0]] = a
            return out

        self._lp, self._lm, self._li = (grow(a, self.n) for a in (self._lp, self._lm, self._li))
        self._prop, self._acc, self._rej, self._dt = (
            grow(a, self.n) for a in (self._prop, self._acc, self._rej, self._dt))
        n_kept = self.n // self.thin
        self._samples, self._sample_step = grow(self._samples, n_kept), grow(self._sample_step,
                                                                             n_kept)
        self._last = time.perf_counter()  # the pause between rounds is no step's time

    def absorb(self, other: ChainRecorder) -> None:
        """Append the steps ``other`` recorded after this recorder's (same layout and thinning).

        Used when draws first meant to be kept become warm-up (the sampler was
        re-adapted after them): the warm-up record then holds every step run.
        """
        if other.layout.size != self.layout.size or other.thin != self.thin:
            raise ValueError("absorb: the recorders differ in layout or thinning")
        n0, n, k0, k = self.steps_done, other.steps_done, self._k, other._k
        self.n = max(self.n, n0)
        self.extend(n0 + n - self.n)
        names = {i: self._names.setdefault(name, len(self._names))
                 for name, i in other._names.items()}
        remap = np.array([names[i] for i in range(len(names))], np.int32)
        for mine, theirs in ((self._lp, other._lp), (self._lm, other._lm), (self._li, other._li),
                             (self._acc, other._acc), (self._rej, other._rej),
                             (self._dt, other._dt)):
            mine[n0:n0 + n] = theirs[:n]
        self._prop[n0:n0 + n] = remap[other._prop[:n]] if n else []
        self._samples[k0:k0 + k] = other._samples[:k]
        self._sample_step[k0:k0 + k] = other._sample_step[:k] + n0
        self._k, self.steps_done = k0 + k, n0 + n
        for attr, key in (("best_image", "log_lik_img"), ("best_landmarks", "log_lik_lm"),
                          ("best_posterior", "log_posterior")):
            theirs = getattr(other, attr)
            if getattr(theirs, key) > getattr(getattr(self, attr), key):
                setattr(self, attr, theirs._replace(step=theirs.step + n0))
        self._last = time.perf_counter()

    def record(self, seconds: float = 0.0) -> ChainRecord:
        """Return the record of the steps done so far."""
        n, k = self.steps_done, self._k
        return ChainRecord(
            self.stage, "mh", self.thin, n, self.layout, self._sample_step[:k].copy(),
            self._samples[:k].copy(), self._lp[:n].copy(), self._lm[:n].copy(),
            self._li[:n].copy(), self._prop[:n].copy(), tuple(self._names), self._acc[:n].copy(),
            self._rej[:n].copy(), self.best_image, self.best_landmarks, self.best_posterior,
            float(seconds), {}, self._dt[:n].copy())


@dataclass
class ChainResult:
    """The stages of one chain, with its seed (``SeedSequence`` entropy and spawn key).

    ``stage1`` is the landmark stage, ``warmup`` the image stage's warm-up
    (proposal scales and the noise model adapted; never part of the
    posterior), ``stage2`` the image stage's kept draws. Each is None when
    skipped (``warmup`` also in files written before warm-up was separate).
    """

    index: int
    seed_entropy: int
    spawn_key: tuple[int, ...]
    stage1: ChainRecord | None
    stage2: ChainRecord | None
    warmup: ChainRecord | None = None
