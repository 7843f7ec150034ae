"""One fit of a face image: landmark stage, then image stage, for several chains.

:func:`fit` wires the pieces: targets (:mod:`mcmcfit.targets.image`,
:mod:`mcmcfit.targets.landmarks`), prior, renderer, the default proposal
schedules (:mod:`proposals.schedule`, with the SH light solver's and the
albedo conditional's data read from the accepted render), the filtered MH
sampler and its recorder, and the diagnostics. Chains run one after the
other in this process and share one renderer (whose compiled shading is
cached per effect set across fits).

This module imports :mod:`albedo_model` (errors, model, params, render.renderer),
:mod:`proposals` (base, light_solver, schedule), the other :mod:`mcmcfit.fitting`
modules but progress, and :mod:`mcmcfit.sampling`, :mod:`mcmcfit.targets` (face,
image, landmarks, priors) and :mod:`mcmcfit.proposal_data` (albedo, light).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import ImageSize, RenderParameter, SHLight
from albedo_model.render.renderer import Renderer
from mcmcfit.proposal_data.albedo import RenderAlbedoData
from mcmcfit.fitting.cache_check import CacheCheck
from mcmcfit.sampling.chain import (
    BestSample, ChainRecord, ChainRecorder, ChainResult, stacked_samples,
)
from mcmcfit.sampling.convergence import convergence
from mcmcfit.sampling.diagnostics import chain_diagnostics
from mcmcfit.targets.face import FaceTarget
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.result import FitResult, sum_acceptance
from mcmcfit.targets.image import ImageLikelihood, prepare_image_target
from mcmcfit.targets.landmarks import FaceBoxTarget, LandmarkGeometry, LandmarkTarget
from mcmcfit.proposal_data.light import RenderLightData
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.fitting.initialisation import (
    check_fit_inputs, initial_params, pose_from_face_box, pose_from_landmarks,
)
from mcmcfit.targets.priors import LogPrior
from mcmcfit.sampling.kernel import init, run
from mcmcfit.fitting.landmark_stage_emcee import run_emcee_stage
from proposals.base import ProposalState
from proposals.light_solver import solve_sh_light
from proposals.schedule import CENTERING_LANDMARKS, default_image_proposal, landmark_stage_proposal

__all__ = ["Progress", "fit", "run_stage"]

#: ``progress(stage, chain, done, total)``: stage is "landmarks" or "image", chain the
#: 0-based chain index, done/total the steps of that stage of that chain.
Progress = Callable[[str, int, int, int], None]

_PROGRESS_EVERY = 25
#: Images whose brightest value is below half an 8-bit step are "all black".
_BLACK = 0.5 / 255.0


def run_stage(rng: np.random.Generator, start: RenderParameter, target: FaceTarget, proposal,
              n_steps: int, *, image: bool, thin: int, layout: ParamLayout,
              progress: Callable[[int, int], None] | None = None,
              check: CacheCheck | None = None) -> ChainRecord:
    """Run one MH stage from ``start`` and return its record (timed).

    Parameters
    ----------
    rng : numpy Generator
    start : RenderParameter
    target : FaceTarget
    proposal : Proposal
    n_steps : int
    image : bool
        The image stage (False: the landmark stage, no render).
    thin : int
        Keep every ``thin``-th sample.
    layout : ParamLayout
        Columns of the kept samples.
    progress : callable ``(done, total)``, optional
    check : CacheCheck, optional
        ``--check-cache``: compare every cached product with a fresh computation
        after each step (raises :class:`~mcmcfit.fitting.cache_check.CacheMismatchError`).
    """
    t0 = time.perf_counter()
    state = init(start, target, image=image)
    recorder = ChainRecorder(layout, n_steps, thin, state, stage="image" if image else "landmarks")
    if check is not None:
        check(-1, state)

    def callback(i, s, info):
        recorder(i, s, info)
        if check is not None:
            check(i, s, info)
        if progress is not None and ((i + 1) % _PROGRESS_EVERY == 0 or i + 1 == n_steps):
            progress(i + 1, n_steps)

    run(rng, state, target, proposal, n_steps, image=image, callback=callback)
    return recorder.record(time.perf_counter() - t0)


def _with_solved_light(target: FaceTarget, params: RenderParameter,
                       data: RenderLightData) -> RenderParameter:
    """``params`` with the least-squares SH light if it renders the target better."""
    rendered = target.init_render(params)
    normals, albedo, colours = data(ProposalState(params, rendered))
    if normals.shape[0] < 20:
        return params
    solved = params._replace(environment_map=SHLight(solve_sh_light(normals, albedo, colours)))
    before = target.log_lik_image(rendered)
    after = target.log_lik_image(target.init_render(solved))
    return solved if after > before else params


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
        :func:`albedo_model.io.image_io.read_image` (linearised internally).
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
    if img.size == 0 or float(img.max()) < _BLACK:
        raise InputError("image is entirely black: there is no face to fit")
    h, w = img.shape[:2]
    check_fit_inputs(w, h, landmarks=landmarks, face_box=face_box,
                     model_landmarks=model.landmark_vertices)
    geometry = LandmarkGeometry(model, threads=1)
    factor: LandmarkTarget | FaceBoxTarget | None = None
    params0 = initial_params(model, w, h, n_shape=cfg.n_shape, n_albedo=cfg.n_albedo,
                             n_expression=cfg.n_expression, model_uri=model_uri)
    used: tuple[str, ...] = ()
    unknown: tuple[str, ...] = ()
    if landmarks is not None:
        factor = LandmarkTarget(geometry, landmarks, sigma=cfg.sigma_lm, image_size=ImageSize(w, h),
                                hidden_probability=cfg.lm_hidden_probability,
                                sigma_factors=landmark_sigma)
        used, unknown = tuple(factor.names), tuple(factor.unknown)
        if unknown:
            warnings.warn(f"ignoring {len(unknown)} landmark(s) the model does not have: "
                          f"{', '.join(unknown)}", stacklevel=2)
        if len(factor.names) >= 2:
            params0 = pose_from_landmarks(geometry, factor.names, factor.observed, params0,
                                          refine=cfg.init_pose == "lsq")
    elif face_box is not None:
        factor = FaceBoxTarget(geometry, face_box, scale_log_sigma=cfg.face_box_scale_sigma,
                               centre_sigma=cfg.face_box_centre_sigma)
        params0 = pose_from_face_box(geometry, face_box, params0)
    layout = ParamLayout.for_params(params0)
    prior = LogPrior(cfg.prior)
    renderer = Renderer(model, specular=cfg.specular, threads=cfg.threads)
    smooth = cfg.sigma_px if cfg.background == "smoothed" else None
    image_target = prepare_image_target(img, bins=cfg.bins, smooth_sigma=smooth)
    image_lik = ImageLikelihood(image_target, kind=cfg.likelihood, sigma=cfg.sigma_px,
                                trim_fraction=cfg.trim_fraction, temperature=cfg.temperature)
    face = FaceTarget(renderer, image_lik, factor, prior)
    lm_only = FaceTarget(renderer, None, factor, prior)
    centring = geometry.point if all(n in geometry.names for n in CENTERING_LANDMARKS) else None
    specular_weight = cfg.specular_weight if renderer.specular else 0.0
    stage1_proposal = landmark_stage_proposal(centring, shape_weight=cfg.stage1_shape_weight,
                                              block_size=cfg.block_size)
    setup_s = time.perf_counter() - t_start

    chains: list[ChainResult] = []
    lm_init: list[RenderParameter] = []
    root = np.random.SeedSequence(seed)
    for ci, ss in enumerate(root.spawn(cfg.chains)):
        rng = np.random.default_rng(ss)
        light_data = RenderLightData(renderer, image_target.linear,
                                     n_points=cfg.solver_points, seed=int(ss.generate_state(1)[0]))
        albedo_data = RenderAlbedoData(renderer, image_target.linear,
                                       n_points=cfg.albedo_points,
                                       seed=int(ss.generate_state(2)[1]))
        image_proposal = default_image_proposal(
            centring, solver_data=light_data, specular_weight=specular_weight,
            block_size=cfg.block_size, solver_sigma=cfg.solver_sigma,
            albedo_data=albedo_data if cfg.albedo_weight > 0 else None,
            albedo_weight=cfg.albedo_weight,
            pixel_sigma=cfg.sigma_px * math.sqrt(cfg.temperature))

        def report(stage: str, ci: int = ci):
            if progress is None:
                return None
            return lambda done, total: progress(stage, ci, done, total)

        rec1 = None
        start = params0
        if factor is not None and cfg.landmark_steps > 0:
            if cfg.stage1 == "emcee":
                walkers = cfg.emcee_walkers
                rec1 = run_emcee_stage(rng, params0, prior, lm_only.log_lik_landmarks, layout,
                                       n_steps=max(1, cfg.landmark_steps // walkers),
                                       n_walkers=walkers, thin=max(1, cfg.thin // walkers),
                                       progress=report("landmarks"))
            else:
                check1 = CacheCheck(lm_only, stage="landmarks") if cfg.check_cache else None
                rec1 = run_stage(rng, params0, lm_only, stage1_proposal, cfg.landmark_steps,
                                 image=False, thin=cfg.thin, layout=layout,
                                 progress=report("landmarks"), check=check1)
            start = rec1.best_posterior.params
        lm_init.append(start)
        rec2 = None
        if cfg.steps > 0:
            if cfg.init_light == "solve":
                start = _with_solved_light(face, start, light_data)
            check2 = CacheCheck(face, (("albedo conditional", albedo_data),
                                       ("SH solver", light_data))) if cfg.check_cache else None
            rec2 = run_stage(rng, start, face, image_proposal, cfg.steps, image=True,
                             thin=cfg.thin, layout=layout, progress=report("image"),
                             check=check2)
        chains.append(ChainResult(ci, int(root.entropy), tuple(int(k) for k in ss.spawn_key),
                                  rec1, rec2))

    return _assemble(cfg, seed, layout, params0, chains, lm_init, used, unknown,
                     setup_s, time.perf_counter() - t_start)


def _assemble(cfg: FitConfig, seed: int, layout: ParamLayout, template: RenderParameter,
              chains: list[ChainResult], lm_init: list[RenderParameter], used, unknown,
              setup_s: float, total_s: float) -> FitResult:
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
                   "stage2": chain_diagnostics(rec2, burn_fraction=cfg.burn_fraction)}
    return FitResult(cfg, int(seed), layout, template, chains, best, best_post, lm_init,
                     mean_params, sum_acceptance(rec2), sum_acceptance(rec1), timings,
                     diagnostics, tuple(used), tuple(unknown),
                     {"stage1": _sum_seconds(rec1), "stage2": _sum_seconds(rec2)},
                     convergence(rec2, burn_fraction=cfg.burn_fraction) if rec2 else {})


def _sum_seconds(records: list[ChainRecord]) -> dict[str, float]:
    out: dict[str, float] = {}
    for r in records:
        for name, t in r.time_by_proposal().items():
            out[name] = out.get(name, 0.0) + t
    return dict(sorted(out.items()))
