"""One fit of a face image: the phases of its chains, in lockstep, and the stop rule.

:func:`fit` validates the inputs, places the mean face from the landmarks (or
face box), and drives the chains (:mod:`mcmcfit.fitting.chain_session`, run
in parallel worker processes by :mod:`mcmcfit.fitting.chain_pool`, one per
chain; :func:`mcmcfit.fitting.driver.drive_chains` runs their phases):

1. landmark stage (prior x landmarks, no render; several starts per chain);
2. the Gaussian sampler (default): the climb to the mode, the region and noise
   model measured at the best chain's mode and set on all chains, the Laplace
   approximation, then a warm-up in windows with step sizes adapted
   (:mod:`mcmcfit.fitting.adaptation`) and a re-centring check after each
   (:meth:`~mcmcfit.fitting.draw_phases.DrawPhases.recentre`); the random-walk
   sampler: a warm-up in ``noise_updates + 1`` phases, after each but the last
   the noise model measured at every chain's best state and the median set on
   all of them, so that every chain targets one posterior
   (:mod:`mcmcfit.targets.noise_model`; ``noise="fixed"`` skips it);
3. kept draws in rounds of ``check_every`` steps, until the convergence rule
   holds on every monitored quantity (:mod:`mcmcfit.sampling.convergence`),
   ``steps`` kept steps per chain, or ``time_budget`` seconds.

This module imports :mod:`albedo_model` (errors, model, params), the
:mod:`mcmcfit.fitting` modules chain_pool, config, driver, effects_choice,
initialisation, problem and result, :mod:`mcmcfit.sampling` (chain, convergence,
derived, diagnostics, param_vector) and :mod:`mcmcfit.targets.landmarks`.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings

import numpy as np
from threadpoolctl import threadpool_limits

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import DirectionalLight
from mcmcfit.fitting.chain_pool import chain_pool
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.driver import Progress, drive_chains
from mcmcfit.fitting.effects_choice import DIRECTIONAL_SHININESS
from mcmcfit.fitting.initialisation import (
    check_fit_inputs, initial_params, pose_from_face_box, pose_from_landmarks,
)
from mcmcfit.fitting.problem import FitProblem, landmark_factor
from mcmcfit.fitting.result import FitResult, sum_acceptance
from mcmcfit.sampling.chain import BestSample, ChainRecord, ChainResult, stacked_samples
from mcmcfit.sampling.convergence import convergence
from mcmcfit.sampling.derived import RegionAlbedo, region_albedo_basis
from mcmcfit.sampling.diagnostics import chain_diagnostics
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.targets.landmarks import FaceBoxTarget, LandmarkGeometry, LandmarkTarget

__all__ = ["Progress", "assemble_result", "fit"]

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
