"""One fit of a face image: the phases of its chains, in lockstep, and the stop rule.

:func:`fit` validates the inputs, places the mean face from the landmarks (or
face box), and drives the chains (:mod:`mcmcfit.fitting.chain_session`, run
in parallel worker processes by :mod:`mcmcfit.fitting.chain_pool`, one per
chain):

1. landmark stage (prior x landmarks, no render; several starts per chain);
2. warm-up in ``noise_updates + 1`` phases: the image stage with step sizes
   adapted per window (:mod:`mcmcfit.fitting.adaptation`); the first phase
   under the configured (provisional) noise model; after each phase but the
   last, every chain measures the noise model at its best state and the
   driver sets the median on all of them, so that every chain targets one
   posterior (:mod:`mcmcfit.targets.noise_model`; ``noise="fixed"`` skips it);
3. kept draws in rounds of ``check_every`` steps, until the convergence rule
   holds on every monitored quantity (:mod:`mcmcfit.sampling.convergence`),
   ``steps`` kept steps per chain, or ``time_budget`` seconds.

This module imports :mod:`albedo_model` (errors, model, params), the
:mod:`mcmcfit.fitting` modules chain_pool, config, initialisation, problem and
result, :mod:`mcmcfit.sampling` (chain, convergence, diagnostics, param_vector)
and :mod:`mcmcfit.targets` (landmarks, noise_model).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import DirectionalLight
from mcmcfit.fitting.chain_pool import chain_pool
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.effects_choice import DIRECTIONAL_SHININESS
from mcmcfit.fitting.initialisation import (
    check_fit_inputs, initial_params, pose_from_face_box, pose_from_landmarks,
)
from mcmcfit.fitting.problem import FitProblem, landmark_factor, provisional_noise
from mcmcfit.fitting.result import FitResult, sum_acceptance
from mcmcfit.sampling.chain import BestSample, ChainRecord, ChainResult, stacked_samples
from mcmcfit.sampling.convergence import convergence
from mcmcfit.sampling.derived import RegionAlbedo, region_albedo_basis
from mcmcfit.sampling.diagnostics import chain_diagnostics
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.targets.landmarks import FaceBoxTarget, LandmarkGeometry, LandmarkTarget
from mcmcfit.targets.noise_model import NoiseModel

__all__ = ["Progress", "assemble_result", "drive_chains", "fit"]

#: ``progress(stage, chain, done, total)``: stage is "landmarks" or "image", chain the
#: 0-based chain index, done/total the steps of that stage of that chain.
Progress = Callable[[str, int, int, int], None]

#: Images whose brightest value is below half an 8-bit step are "all black".
BLACK_LEVEL = 0.5 / 255.0


def _best(samples: list[BestSample], key) -> BestSample:
    return max(samples, key=key)


def fit(image: np.ndarray, landmarks, model: MorphableModel, *, config: FitConfig | None = None,
        seed: int = 0, progress: Progress | None = None, face_box=None,
        model_uri: str = "", landmark_sigma=None) -> FitResult:
    """Fit ``model`` to one photograph.

    Parameters
    ----------
    image : (H, W, 3) float array in [0, 1]
        The photograph, gamma-encoded sRGB as read by
        :func:`albedo_model.io.image_io.read_image` (linearised internally,
        unless the model's colour is an sRGB texture: ``config.model_colour``).
    landmarks : list of Landmark, mapping name -> (x, y), or None
        2-D target landmarks in pixels (x right, y down); occluded ones ignored.
    model : MorphableModel
    config : FitConfig, optional
    seed : int
        Root seed; the run is reproducible from it.
    progress : callable ``(stage, chain, done, total)``, optional
    face_box : (x0, y0, x1, y1), optional
        Used for the pose guess and the landmark stage when ``landmarks`` is None.
    model_uri : str
        Written into the parameters' ``momo.model_uri``.
    landmark_sigma : mapping name -> float, optional
        Per-landmark factors of ``config.sigma_lm`` (e.g. the reliability of
        detected points, :data:`mcmcfit.detection.basel_names.BASEL_POINTS`); 1 for
        names not in it.

    Returns
    -------
    FitResult

    Raises
    ------
    InputError
        Bad or all-black image, fewer than 3 target landmarks the model knows
        (those it lacks are named in a warning and ignored), bad configuration.
    """
    # One BLAS thread while sampling: OpenBLAS workers spin after every product and
    # take the second core from Embree and XLA (stage 2 about 15 % faster). The
    # default mcmcfit sets on import comes too late when numpy was imported first.
    with threadpool_limits(limits=1, user_api="blas"):
        return _fit(image, landmarks, model, config=config, seed=seed, progress=progress,
                    face_box=face_box, model_uri=model_uri,
                    landmark_sigma=landmark_sigma)


def _fit(image: np.ndarray, landmarks, model: MorphableModel, *, config: FitConfig | None,
         seed: int, progress: Progress | None, face_box, model_uri: str,
         landmark_sigma=None) -> FitResult:
    """:func:`fit` without the BLAS thread limit."""
    cfg = config or FitConfig()
    t_start = time.perf_counter()
    img = np.asarray(image, np.float64)
    if img.ndim != 3 or img.shape[2] != 3:
        raise InputError(f"image must have shape (H, W, 3), got {img.shape}")
    if not np.all(np.isfinite(img)):
        raise InputError("image contains NaN or infinite values")
    if img.size == 0 or float(img.max()) < BLACK_LEVEL:
        raise InputError("image is entirely black: there is no face to fit")
    h, w = img.shape[:2]
    check_fit_inputs(w, h, landmarks=landmarks, face_box=face_box,
                     model_landmarks=model.landmark_vertices)
    geometry = LandmarkGeometry(model, threads=1)
    params0 = initial_params(model, w, h, n_shape=cfg.n_shape, n_albedo=cfg.n_albedo,
                             n_expression=cfg.n_expression, model_uri=model_uri)
    params0 = params0._replace(directional_light=DirectionalLight(shininess=DIRECTIONAL_SHININESS))
    layout0 = dataclasses.replace(ParamLayout.for_params(params0), directional=cfg.effects != "sh")
    problem = FitProblem(img, landmarks, face_box, landmark_sigma, model, cfg, params0, layout0)
    factor = landmark_factor(problem, geometry)
    used: tuple[str, ...] = ()
    unknown: tuple[str, ...] = ()
    if isinstance(factor, LandmarkTarget):
        used, unknown = tuple(factor.names), tuple(factor.unknown)
        if unknown:
            warnings.warn(f"ignoring {len(unknown)} landmark(s) the model does not have: "
                          f"{', '.join(unknown)}", stacklevel=2)
        if len(factor.names) >= 2:
            params0 = pose_from_landmarks(geometry, factor.names, factor.observed, params0,
                                          refine=cfg.init_pose == "lsq")
    elif isinstance(factor, FaceBoxTarget):
        params0 = pose_from_face_box(geometry, face_box, params0)
    problem = dataclasses.replace(problem, start=params0)
    layout = problem.layout
    root = np.random.SeedSequence(seed)
    seeds = root.spawn(cfg.chains)
    regions = region_albedo_basis(model)
    pool = chain_pool(problem, seeds, processes=cfg.parallel)
    setup_s = time.perf_counter() - t_start
    try:
        results, noise, stopping = drive_chains(pool, cfg, layout, t_start, progress, regions)
    finally:
        pool.close()
    lm_init = [r.stage1.best_posterior.params if r.stage1 is not None else params0
               for r in results]
    return assemble_result(cfg, seed, layout, params0, results, lm_init, used, unknown,
                           setup_s, time.perf_counter() - t_start, noise, stopping, regions)


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
            first = (warm * 3) // 5 if cfg.widen and cfg.adapt else warm
            pool.call("warmup", first, window=cfg.adapt_window, adapt=cfg.adapt)
            if first < warm:
                _report(progress, "image", k, first, total)
                draws = pool.call("warmup_draws", 2.0 / 3.0)
                stopping["widening"] = pool.call("widen", draws)
                pool.call("warmup", warm - first, window=cfg.adapt_window, adapt=cfg.adapt)
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
    return NoiseModel(sigma, temperature, "estimated", n_face, n_face / temperature)


def assemble_result(cfg: FitConfig, seed: int, layout, template,
                    chains: list[ChainResult], lm_init: list, used, unknown,
                    setup_s: float, total_s: float, noise, stopping: dict,
                    regions: RegionAlbedo | None = None) -> FitResult:
    """Collect the chains' records into a :class:`FitResult` (a single or a joint fit's layout)."""
    stopping.setdefault("effects", {"decision": "sh", "reason": "no climb to the mode"})
    if getattr(layout, "directional", False):
        chains, layout, template = light_effects_of(chains, layout, template,
                                                    stopping["effects"]["decision"])
    rec1 = [c.stage1 for c in chains if c.stage1 is not None]
    rec2 = [c.stage2 for c in chains if c.stage2 is not None]
    last = rec2 or rec1
    if rec2:
        best = _best([r.best_image for r in rec2], key=lambda b: b.log_lik_img)
    elif rec1:
        best = _best([r.best_posterior for r in rec1], key=lambda b: b.log_posterior)
    else:
        best = BestSample(template, -1, math.nan, math.nan, math.nan)
    best_post = (_best([r.best_posterior for r in last], key=lambda b: b.log_posterior)
                 if last else best)
    mean_params = None
    if rec2 and all(r.samples.shape[0] for r in rec2):
        pooled = stacked_samples(rec2, layout.size, discard=cfg.burn_fraction, flat=True)
        if pooled.shape[0]:
            mean_params = layout.from_vector(pooled.mean(axis=0), template)
    s1 = sum(r.seconds for r in rec1)
    s2 = sum(r.seconds for r in rec2)
    n1 = sum(r.steps if r.sampler == "mh" else int(r.extra["iterations"] * r.extra["n_walkers"])
             for r in rec1)
    n2 = sum(r.steps for r in rec2)
    timings = {"setup_s": setup_s, "stage1_s": s1, "stage2_s": s2, "total_s": total_s,
               "stage1_steps_per_s": n1 / s1 if s1 > 0 else math.nan,
               "stage2_steps_per_s": n2 / s2 if s2 > 0 else math.nan}
    diagnostics = {"stage1": chain_diagnostics(rec1, burn_fraction=cfg.burn_fraction),
                   "stage2": chain_diagnostics(rec2, burn_fraction=cfg.burn_fraction,
                                               model=regions)}
    return FitResult(cfg, int(seed), layout, template, chains, best, best_post, lm_init,
                     mean_params, sum_acceptance(rec2), sum_acceptance(rec1), timings,
                     diagnostics, tuple(used), tuple(unknown),
                     {"stage1": _sum_seconds(rec1), "stage2": _sum_seconds(rec2)},
                     convergence(rec2, burn_fraction=cfg.burn_fraction, model=regions)
                     if rec2 else {},
                     noise.to_dict(), stopping)


def light_effects_of(chains: list[ChainResult], layout, template, decision: str):
    """Return chains, layout and template fitting the effects chosen (``stopping["effects"]``).

    The chains record a directional light's columns from the start (zeros
    while it is off); without one they are dropped, with one the template
    carries the light of the last kept draw (so that ``ParamLayout.for_params``
    of the template is the layout again, as ``chain.h5`` reads it).
    """
    if decision != "sh+directional":
        plain = dataclasses.replace(layout, directional=False)
        out = []
        for c in chains:
            parts = {name: dataclasses.replace(getattr(c, name), layout=plain,
                                               samples=getattr(c, name).samples[:, :plain.size])
                     for name in ("stage1", "warmup", "stage2") if getattr(c, name) is not None}
            out.append(dataclasses.replace(c, **parts))
        return out, plain, template
    last = next((c.stage2.samples[-1] for c in chains
                 if c.stage2 is not None and c.stage2.samples.shape[0]), None)
    if last is not None:
        template = template._replace(
            directional_light=layout.from_vector(last, template).directional_light)
    return chains, layout, template


def _sum_seconds(records: list[ChainRecord]) -> dict[str, float]:
    out: dict[str, float] = {}
    for r in records:
        for name, t in r.time_by_proposal().items():
            out[name] = out.get(name, 0.0) + t
    return dict(sorted(out.items()))
