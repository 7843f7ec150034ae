"""The fit driver: the phases of every chain in lockstep, the warm-up's checks and the stop rule.

:func:`drive_chains` runs a fit's chains (a single fit's or a joint fit's
sessions, in this process or in worker processes) through the landmark stage,
the climb to the mode and the Laplace approximation (Gaussian sampler), the
warm-up with its re-centring checks, and the kept draws in rounds until the
convergence rule holds, ``steps`` or ``time_budget``; see :mod:`mcmcfit.fitting.fit`.

This module imports :mod:`mcmcfit.fitting` (config, mode, problem) and
:mod:`mcmcfit.sampling` (chain, convergence, derived) and :mod:`mcmcfit.targets.noise_model`.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.mode import ADOPT_GAP
from mcmcfit.fitting.problem import provisional_noise
from mcmcfit.sampling.chain import ChainResult
from mcmcfit.sampling.convergence import convergence
from mcmcfit.sampling.derived import RegionAlbedo
from mcmcfit.targets.noise_model import NoiseModel

__all__ = ["MAX_RECENTRINGS", "RECENTRE_GAP", "Progress", "drive_chains"]

#: ``progress(stage, chain, done, total)``: stage is "landmarks" or "image", chain the
#: 0-based chain index, done/total the steps of that stage of that chain.
Progress = Callable[[str, int, int, int], None]


def _report(progress: Progress | None, stage: str, n_chains: int, done: int, total: int) -> None:
    if progress is not None:
        for ci in range(n_chains):
            progress(stage, ci, done, total)


def drive_chains(pool, cfg: FitConfig, layout, t_start: float, progress: Progress | None,
                 regions: RegionAlbedo | None = None) -> tuple[list[ChainResult], NoiseModel, dict]:
    """Run the phases of every chain in lockstep; return the chains, noise model and stop reason.

    ``pool`` runs the calls on every chain's session (a single fit's, or a joint
    fit's: :class:`~mcmcfit.fitting.joint_session.JointChainSession`, whose noise
    model is a :class:`~mcmcfit.fitting.joint_problem.JointNoise`).
    """
    k = cfg.chains
    if cfg.landmark_steps > 0:
        pool.call("landmarks")
        _report(progress, "landmarks", k, cfg.landmark_steps, cfg.landmark_steps)
    noise = provisional_noise(cfg)
    stopping = {"reason": "no image stage", "kept_steps": 0, "checks": []}
    if cfg.steps == 0:
        return pool.call("finish"), noise, stopping
    pool.call("begin_image")
    warm = cfg.warmup
    total = warm + cfg.steps
    if cfg.sampler != "random-walk":
        noise = _prepare_gaussian(pool, cfg, stopping)
        if warm:
            fisher = cfg.metric == "fisher" and cfg.sampler == "gaussian"
            first = (warm * 3) // 5 if (cfg.widen or fisher) and cfg.adapt else warm
            rest = warm - first
            ran = _warm_up_recentring(pool, cfg, first, stopping)
            warm, total = ran + rest, total + ran - first
            if rest:
                _report(progress, "image", k, ran, total)
                if fisher:
                    stopping["widening"] = _widen_by_fisher(pool, ran)
                else:
                    draws = pool.call("warmup_draws", 2.0 / 3.0)
                    stopping["widening"] = pool.call("widen", draws)
                pool.call("warmup", rest, window=cfg.adapt_window, adapt=cfg.adapt)
            _report(progress, "image", k, warm, total)
    else:
        phases = cfg.noise_updates + 1 if cfg.noise == "estimated" and warm > 0 else 1
        done = 0
        for phase in range(phases):
            n = (warm * (phase + 1)) // phases - done
            if n:
                pool.call("warmup", n, window=cfg.adapt_window, adapt=cfg.adapt)
                done += n
                _report(progress, "image", k, done, total)
            if phase < phases - 1:
                noise = _pooled(pool.call("measure_noise"))
                pool.call("set_noise", noise)
    kept = 0
    reason = "max steps"
    while kept < cfg.steps:
        n = min(cfg.check_every, cfg.steps - kept)
        elapsed = time.perf_counter() - t_start
        if cfg.time_budget is not None and kept > 0:
            per_step = (elapsed - stopping.get("kept_start", elapsed)) / kept
            if elapsed + per_step * n > cfg.time_budget:
                reason = "time budget"
                break
        stopping.setdefault("kept_start", elapsed)
        records = pool.call("draw", n)
        kept += n
        _report(progress, "image", k, warm + kept, total)
        verdict = convergence(records, burn_fraction=cfg.burn_fraction, model=regions)
        stopping["checks"].append({"kept_steps": kept, "seconds": time.perf_counter() - t_start,
                                   "max_rhat": verdict.get("max_rhat"),
                                   "min_ess_bulk": verdict.get("min_ess_bulk"),
                                   "min_ess_tail": verdict.get("min_ess_tail")})
        if cfg.stop_when_converged and verdict.get("converged"):
            reason = "converged"
            break
        if (cfg.widen_at and kept >= cfg.widen_at and "widening_kept" not in stopping
                and cfg.sampler == "gaussian" and cfg.adapt):
            stopping["widening_kept"] = _widen_from_kept(pool, cfg)
            if stopping["widening_kept"]["ratios"]:
                stopping["checks"][-1]["restarted"] = True
                kept = 0
    stopping.pop("kept_start", None)
    stopping.update(reason=reason, kept_steps=kept, warmup_steps=warm)
    return pool.call("finish"), noise, stopping


#: Most re-centrings of a fit's warm-up (each adds at most one window of warm-up).
MAX_RECENTRINGS = 3
#: A chain re-centres when its warm-up's best draw beats its mode by more than this (nats).
RECENTRE_GAP = ADOPT_GAP


def _warm_up_recentring(pool, cfg: FitConfig, n_steps: int, stopping: dict) -> int:
    """Run ``n_steps`` warm-up steps in windows, re-centring the chains' approximations after each.

    See :meth:`~mcmcfit.fitting.draw_phases.DrawPhases.recentre`. A chain
    re-centred in the last window gets one more window on its new
    approximation. Records every check in ``stopping["recentring"]``; returns
    the warm-up steps run.
    """
    if not (cfg.recentre and cfg.adapt):
        pool.call("warmup", n_steps, window=cfg.adapt_window, adapt=cfg.adapt)
        return n_steps
    window = max(1, cfg.adapt_window)
    done, target, moves, checks = 0, n_steps, 0, []
    while done < target:
        n = min(window, target - done)
        pool.call("warmup", n, window=window, adapt=True)
        done += n
        if moves < MAX_RECENTRINGS:
            t0 = time.perf_counter()
            found = pool.call("recentre", RECENTRE_GAP)
            moved = sum(bool(r["moved"]) for r in found)
            checks.append({"warmup_steps": done, "gains": [r["gain"] for r in found],
                           "moved": [bool(r["moved"]) for r in found],
                           "seconds": time.perf_counter() - t0})
            moves += moved > 0
            if moved and target - done < window:
                target = done + window
    stopping["recentring"] = checks
    return done


#: Warm-up draws per chain whose gradients :func:`_widen_by_fisher` evaluates (~30 ms each).
FISHER_DRAWS = 150


def _widen_by_fisher(pool, ran: int) -> list[dict]:
    """Widen every chain's approximation from all chains' warm-up draws and gradients at them.

    Each chain evaluates the exact gradient at its last :data:`FISHER_DRAWS`
    warm-up draws (at most half of ``ran``, the warm-up steps so far); every chain then
    widens with the same pooled estimate
    (:func:`proposals.laplace.widening.widened_by_fisher`). Returns each chain's record
    (as :meth:`~mcmcfit.fitting.draw_phases.DrawPhases.widen`, plus ``seconds``).
    """
    t0 = time.perf_counter()
    found = pool.call("warmup_gradients", max(2, min(FISHER_DRAWS, ran // 2)))
    draws, grads = [f[0] for f in found], [f[1] for f in found]
    if min(d.shape[0] for d in draws) < 2:  # a warm-up too short (or thinned) to estimate from
        out = [{"ratios": [], "largest": None, "edge": None, "n_draws": 0}] * len(draws)
    else:
        out = pool.call("widen", draws, 0.25, grads)
    return [{**o, "seconds": time.perf_counter() - t0} for o in out]


#: Effective draws per kept draw assumed when widening from the kept draws: the slow
#: directions widening is for are the draws' most correlated (ESS/draw ~0.01-0.05 there).
KEPT_EFFECTIVE_FRACTION = 0.1
#: Warm-up steps after widening from the kept draws (the moves' step sizes re-adapted).
REWARM_STEPS = 100


def _widen_from_kept(pool, cfg: FitConfig) -> dict:
    """Widen every chain's approximation where the kept draws so far are wider; restart if so.

    The draws of all chains (their last three quarters) go into one estimate
    (:func:`proposals.laplace.widening.widened_by_draws`). When a direction is
    widened, every chain's kept draws so far become warm-up, the moves' step
    sizes are re-adapted for :data:`REWARM_STEPS` steps and the kept draws
    start again, so the kept chain is one frozen kernel throughout.
    """
    draws = pool.call("kept_draws", 0.75)
    found = pool.call("widen", draws, KEPT_EFFECTIVE_FRACTION)[0]
    out = {"ratios": found["ratios"], "largest": found["largest"], "edge": found["edge"],
           "n_draws": found["n_draws"], "restarted_after": 0}
    if found["ratios"]:
        out["restarted_after"] = int(pool.call("restart_kept")[0])
        pool.call("warmup", REWARM_STEPS, window=cfg.adapt_window, adapt=True)
    return out


#: Rounds of (region, noise model) measured at the best chain's mode, each followed by a climb.
TARGET_ROUNDS = 2


def _prepare_gaussian(pool, cfg: FitConfig, stopping: dict) -> NoiseModel:
    """Climb every chain to the mode, fix the region and noise model, fit the Laplace approximations.

    The region and the noise model are measured at the best chain's mode and
    set on every chain (one posterior for all), twice: the second time at the
    mode of the posterior the first one defined. Returns the noise model in use.
    """
    t0 = time.perf_counter()
    climbs = pool.call("climb")
    best = int(np.argmax([c["score"] for c in climbs]))
    stopping["effects"] = pool.call("choose_effects")[best]
    pool.call("set_effects", stopping["effects"]["decision"])
    rounds = []
    noise = None
    for _ in range(TARGET_ROUNDS):
        region, noise = pool.call("measure_target")[best]
        best_params = pool.call("mode_params")[best]
        dens = pool.call("set_region", region, noise, best_params)
        rounds.append({"best_chain": best, "log_densities": [float(d) for d in dens],
                       "region_pixels": int(np.count_nonzero(region)),
                       "sigma": noise.sigma, "temperature": noise.temperature})
        best = int(np.argmax(dens))
    prepared = pool.call("prepare_gaussian")
    stopping["mode"] = {"climb_scores": [c["score"] for c in climbs],
                        "climb_traces": [c["trace"] for c in climbs], "rounds": rounds,
                        "dimension": prepared[0]["dimension"],
                        "metric": [p.get("metric") for p in prepared],
                        "seconds": time.perf_counter() - t0}
    return noise


def _pooled(noises: list[NoiseModel]) -> NoiseModel:
    """One noise model for every chain: the median of their estimates (the same posterior for all)."""
    sigma = float(np.median([n.sigma for n in noises]))
    temperature = float(np.median([n.temperature for n in noises]))
    n_face = int(np.median([n.n_face for n in noises]))
    sensor = float(np.median([n.sensor_sigma for n in noises]))
    return NoiseModel(sigma, temperature, "estimated", n_face, n_face / temperature,
                      sensor_sigma=sensor)
