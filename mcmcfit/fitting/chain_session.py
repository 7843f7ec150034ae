"""One chain of a fit, run in phases the driver asks for: landmarks, warm-up, kept draws.

A :class:`ChainSession` owns one chain's renderer, targets, proposals, random
generator and records. The fit driver (:mod:`mcmcfit.fitting.driver`) calls its
methods in lockstep over all chains, in this process or in worker processes
(:mod:`mcmcfit.fitting.chain_pool`): the same calls in the same order give the
same chains either way.

Phases:

1. :meth:`~ChainSession.landmarks` -- the landmark stage (prior x landmarks, no render);
2. :meth:`~ChainSession.begin_image` -- the image stage's start (least-squares light);
3. :meth:`~ChainSession.warmup` -- windows of image-stage steps after each of which the
   step-size multipliers are adapted (:mod:`mcmcfit.fitting.adaptation`); recorded
   as the ``warmup`` record, never part of the posterior;
4. :meth:`~ChainSession.measure_noise` / :meth:`~ChainSession.set_noise` -- the
   likelihood's scale measured at the warm-up's best state, then fixed
   (:mod:`mcmcfit.targets.noise_model`; the driver pools the chains' estimates so
   that every chain targets the same posterior);
5. :meth:`~ChainSession.draw` -- kept draws, in rounds, until the driver's stop rule;
6. :meth:`~ChainSession.finish` -- the :class:`~mcmcfit.sampling.chain.ChainResult`.

This module imports :mod:`albedo_model` (default_model, params), :mod:`mcmcfit.fitting` (adaptation,
cache_check, landmark_stage_emcee, landmark_starts, problem), :mod:`mcmcfit.proposal_data`,
:mod:`mcmcfit.sampling` (chain, kernel), :mod:`mcmcfit.targets` (gradient, landmarks,
noise_model, robust_foreground) and
:mod:`proposals` (base, light_solver, schedule).
"""

from __future__ import annotations


import numpy as np

from albedo_model.default_model import cache_dir
from albedo_model.params import RenderParameter, SHLight
from mcmcfit.fitting.adaptation import (
    MALA_BLOCKS, MIN_PROPOSED, adapt_scales, adapt_step, family_counts, initial_diagonal,
)
from mcmcfit.targets.gradient import posterior_gradient
from mcmcfit.fitting.cache_check import CacheCheck
from mcmcfit.fitting.landmark_stage_emcee import run_emcee_stage
from mcmcfit.fitting.effects_phase import EffectPhases
from mcmcfit.fitting.gaussian_stage import GaussianPhases
from mcmcfit.fitting.landmark_starts import DEFAULT_STARTS, landmark_stage
from mcmcfit.fitting.mode import ModeResult
from mcmcfit.targets.landmarks import LandmarkTarget
from mcmcfit.fitting.problem import FitProblem, Posterior, build_posterior, provisional_noise
from mcmcfit.proposal_data.albedo import RenderAlbedoData
from mcmcfit.proposal_data.face_pixels import unsaturated
from mcmcfit.proposal_data.light import RenderLightData
from mcmcfit.proposal_data.light_system import RenderLightSystem
from mcmcfit.targets.robust_foreground import face_weights
from mcmcfit.sampling.chain import ChainRecord, ChainRecorder, ChainResult
from mcmcfit.sampling.kernel import ChainState, init
from mcmcfit.targets.curvature import PosteriorCurvature, SceneCaster, coordinate_gradient
from mcmcfit.targets.noise_model import NoiseModel, estimate_noise
from proposals.base import ProposalState
from proposals.gradient import MALA, block_vector
from proposals.light_conditional import LightConditional
from proposals.light_solver import solve_sh_light
from proposals.laplace.moves import GaussianApproximation
from proposals.laplace.schedule import GAUSSIAN_TARGETS, gaussian_image_proposal
from proposals.schedule import (
    CENTERING_LANDMARKS, FAMILIES, default_image_proposal, family_of, landmark_stage_proposal,
)

__all__ = ["ChainSession", "use_compilation_cache"]


def use_compilation_cache() -> None:
    """Keep XLA's compiled programs in ``<cache>/jax`` (``albedo_model.default_model.cache_dir``).

    Every chain process compiles the same shading and gradient programs (tens of
    seconds for the gradient of the whole geometry); JAX's persistent cache makes
    that a one-time cost per machine. Compilations over 0.2 s are kept.
    """
    import jax

    if jax.config.jax_compilation_cache_dir is None:
        jax.config.update("jax_compilation_cache_dir", str(cache_dir() / "jax"))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)


class ChainSession(EffectPhases, GaussianPhases):
    """One chain: its targets, proposals, state and records.

    Parameters
    ----------
    problem : FitProblem
    index : int
        Chain index (0-based).
    seed : numpy SeedSequence
        This chain's seed (a child of the fit's root seed).
    threads : int, optional
        Ray-casting threads (1 per chain when chains run in parallel processes).
    """

    def __init__(self, problem: FitProblem, index: int, seed: np.random.SeedSequence, *,
                 threads: int | None = None):
        use_compilation_cache()
        self.problem, self.index, self.seed = problem, int(index), seed
        self.cfg = problem.config
        self.rng = np.random.default_rng(seed)
        self._data_seeds = [int(x) for x in seed.generate_state(2)]
        self.posterior: Posterior = build_posterior(problem, provisional_noise(self.cfg),
                                                    threads=threads)
        geometry = self.posterior.geometry
        self.centring = (geometry.point if all(n in geometry.names for n in CENTERING_LANDMARKS)
                         else None)
        self.scales: dict[str, float] = {f: 1.0 for f in FAMILIES}
        self.mala_step = float(self.cfg.mala_step)
        self.mala_diag = initial_diagonal(problem.start)
        self._gradient = None
        self._hmc_gradient = None
        self.region: np.ndarray | None = None
        self.coords = None
        self.approx: GaussianApproximation | None = None
        self.mode: ModeResult | None = None
        self._caster: SceneCaster | None = None
        self._build_data()
        self._build_proposal()
        self.stage1: ChainRecord | None = None
        self.start: RenderParameter = problem.start
        self.state: ChainState | None = None
        self._warm: ChainRecorder | None = None
        self._kept: ChainRecorder | None = None
        self._t_warm = self._t_kept = 0.0
        self._phase_start = 0
        self._pending: dict[str, tuple[int, int]] = {}

    # -- proposals -------------------------------------------------------------------
    def _build_data(self) -> None:
        """Build the data-driven proposals' data: functions of the render and the image only.

        Built once: neither the noise model nor the step sizes change them, so
        their kept systems survive every rebuild of the proposal.
        """
        cfg, post = self.cfg, self.posterior
        weights = self._face_weights()
        self.light_data = RenderLightData(post.renderer, post.image_target.linear,
                                          n_points=cfg.solver_points, seed=self._data_seeds[0])
        self.light_system = RenderLightSystem(post.image_target.linear, region=self.region,
                                              weights=weights, directional=True)
        self.albedo_data = RenderAlbedoData(post.renderer, post.image_target.linear,
                                            n_points=cfg.albedo_points, seed=self._data_seeds[1],
                                            region=self.region, weights=weights)

    def _face_weights(self):
        """Return a robust foreground's face probabilities (H W,) at the mode (fixed weights), or None."""
        lik = self.posterior.face.image_likelihood
        if lik is None or not lik.robust or getattr(self, "mode", None) is None:
            return None
        out = self.posterior.renderer.render(self.mode.params)
        return face_weights(lik, None, np.asarray(out.image, np.float64).reshape(-1, 3),
                            lik.target.linear.reshape(-1, 3))

    def _build_proposal(self) -> None:
        cfg, post = self.cfg, self.posterior
        specular_weight = cfg.specular_weight if post.renderer.specular else 0.0
        light_conditional = None
        if cfg.light_conditional_weight > 0:
            k = self.problem.start.environment_map.coefficients.shape[0]
            mean, sd = post.face.prior.light_gaussian(k)
            light_conditional = LightConditional(self.light_system, mean, sd,
                                                 sigma=post.pixel_sigma)
        if self.approx is not None:
            self.proposal = gaussian_image_proposal(
                self.coords, self.approx, scales=self.scales, albedo_data=self.albedo_data,
                pixel_sigma=post.pixel_sigma, light_conditional=light_conditional,
                pcn_weight=cfg.pcn_weight, block_weight=cfg.block_weight,
                albedo_weight=0.5 * cfg.conditional_weight,
                light_conditional_weight=0.5 * cfg.conditional_weight,
                gradient=self._coordinate_gradient() if cfg.hmc_weight > 0 else None,
                hmc_weight=cfg.hmc_weight, hmc_leapfrog=cfg.hmc_leapfrog,
                hmc_random_steps=cfg.hmc_random_steps, contrast_light=cfg.contrast_light,
                offset_sd=post.face.prior.config.offset_sigma if cfg.albedo_offsets else None)
            self.family = family_of(self.proposal)
            return
        extra = []
        if cfg.mala_weight > 0:
            if self._gradient is None:
                self._gradient = posterior_gradient(post.face, MALA_BLOCKS, threads=1)
            self.mala = MALA(self._gradient, MALA_BLOCKS, self.mala_step, self.mala_diag,
                             name="mala")
            extra.append((cfg.mala_weight, self.mala))
        self.proposal = default_image_proposal(
            self.centring, solver_data=self.light_data, specular_weight=specular_weight,
            block_size=cfg.block_size, solver_sigma=cfg.solver_sigma,
            albedo_data=self.albedo_data if cfg.albedo_weight > 0 else None,
            albedo_weight=cfg.albedo_weight, pixel_sigma=post.pixel_sigma, scales=self.scales,
            light_conditional=light_conditional,
            light_conditional_weight=cfg.light_conditional_weight, extra_moves=extra)
        self.family = {**family_of(self.proposal), "mala": "mala"}

    def _coordinate_gradient(self):
        """Return the posterior's gradient in the sampling coordinates (built once, for the HMC move)."""
        if self._hmc_gradient is None:
            curvature = PosteriorCurvature(self.posterior.face, self.coords.layout,
                                           caster=self._scene_caster())
            triangles = (curvature.region_triangles(self.mode.params)
                         if self.cfg.hmc_triangles == "mode" else None)
            self._hmc_gradient = coordinate_gradient(curvature, self.coords, triangles)
        return self._hmc_gradient

    def _check(self) -> CacheCheck | None:
        if not self.cfg.check_cache:
            return None
        return CacheCheck(self.posterior.face, (("albedo conditional", self.albedo_data),
                                                ("SH solver", self.light_data),
                                                ("light conditional", self.light_system)))

    # -- phases ----------------------------------------------------------------------
    def landmarks(self) -> float:
        """Run the landmark stage; the image stage starts from its best posterior sample.

        Returns
        -------
        float
            The best log posterior (prior x landmarks) found.
        """
        cfg, post = self.cfg, self.posterior
        if post.landmarks_only.landmarks is None or cfg.landmark_steps == 0:
            return float("nan")
        layout = self.problem.layout
        if cfg.stage1 == "emcee":
            walkers = cfg.emcee_walkers
            rec = run_emcee_stage(self.rng, self.start, post.landmarks_only.log_prior,
                                  post.landmarks_only.log_lik_landmarks, layout,
                                  n_steps=max(1, cfg.landmark_steps // walkers),
                                  n_walkers=walkers, thin=max(1, cfg.thin // walkers))
        else:
            proposal = landmark_stage_proposal(self.centring,
                                               shape_weight=cfg.stage1_shape_weight,
                                               block_size=cfg.block_size)
            check = CacheCheck(post.landmarks_only, stage="landmarks") if cfg.check_cache \
                else None
            # a face box says nothing about yaw or distance: several starts would only
            # pick among poses it cannot tell apart
            starts = DEFAULT_STARTS if isinstance(post.landmarks_only.landmarks,
                                                  LandmarkTarget) else ("guess",)
            rec, _ = landmark_stage(self.rng, self.start, post.landmarks_only, proposal,
                                    cfg.landmark_steps, layout=layout, thin=cfg.thin,
                                    check=check, starts=starts)
        self.stage1 = rec
        self.start = rec.best_posterior.params
        return float(rec.best_posterior.log_posterior)

    def begin_image(self) -> float:
        """Start the image stage (light solved at the start if that renders better).

        Returns
        -------
        float
            The start's image log likelihood.
        """
        face = self.posterior.face
        start = self.start
        if self.cfg.init_light == "solve":
            start = _with_solved_light(face, start, self.light_data)
        self.state = init(start, face, image=True)
        return self.state.log_lik_img

    def warmup(self, n_steps: int, *, window: int, adapt: bool = True) -> dict[str, float]:
        """Run ``n_steps`` warm-up steps in windows, adapting the step sizes after each.

        Returns
        -------
        dict family -> step-size multiplier after the warm-up so far.
        """
        if self._warm is None:
            self._warm = ChainRecorder(self.problem.layout, 0, self.cfg.thin, self.state,
                                       stage="warmup")
        done = 0
        while done < n_steps:
            n = min(window, n_steps - done)
            first = self._warm.steps_done
            self._advance(self._warm, n)
            if adapt:
                counts = family_counts(*self._warm.proposals_since(first), self.family)
                for fam, (n_prop, n_acc) in counts.items():
                    p0, a0 = self._pending.get(fam, (0, 0))
                    self._pending[fam] = (p0 + n_prop, a0 + n_acc)
                new = adapt_scales(self.scales, self._pending, families=FAMILIES,
                                   targets=GAUSSIAN_TARGETS)
                mala_step = adapt_step(self.mala_step, self._pending.get("mala", (0, 0)))
                for fam in (*FAMILIES, "mala"):  # a family's counts restart once used
                    if self._pending.get(fam, (0, 0))[0] >= MIN_PROPOSED:
                        self._pending.pop(fam)
                if new != self.scales or mala_step != self.mala_step:
                    self.scales, self.mala_step = new, mala_step
                    self._build_proposal()
            done += n
        if adapt:
            self.adapt_preconditioner()
        return dict(self.scales)

    def adapt_preconditioner(self) -> None:
        """Set the gradient moves' preconditioner to the variances of the warm-up draws so far.

        The second half of the warm-up's kept samples is used (at least 20);
        each variance is floored at 1e-4 of the initial diagonal (a coordinate
        that never moved keeps a usable scale).
        """
        if self._warm is None or self.cfg.mala_weight <= 0:
            return
        rec = self._warm.record()
        if rec.samples.shape[0] < 40:
            return
        half = rec.samples[rec.samples.shape[0] // 2:]
        layout, start = self.problem.layout, self.problem.start
        vectors = np.array([block_vector(layout.from_vector(v, start), MALA_BLOCKS)
                            for v in half])
        floor = 1e-4 * initial_diagonal(start)
        self.mala_diag = np.maximum(vectors.var(axis=0), floor)
        self._build_proposal()

    def measure_noise(self) -> NoiseModel:
        """Measure the likelihood's scale at the best state since the noise model last changed.

        "Best" is the kept warm-up sample of highest image likelihood under the
        current noise model (a posterior draw's residual would include the
        posterior's own spread).
        """
        params = self.state.params
        if self._warm is not None and self._warm.steps_done > self._phase_start:
            rec = self._warm.record()
            sel = rec.sample_step >= self._phase_start
            if sel.any():
                i = int(np.argmax(np.where(sel, rec.log_lik_img[rec.sample_step], -np.inf)))
                params = self.problem.layout.from_vector(rec.samples[i], self.problem.start)
        rendered = self.posterior.renderer.render(params)
        target = self.posterior.image_target.linear
        usable = unsaturated(target.reshape(-1, 3)).reshape(target.shape[:2])
        # the side render made ``params`` the renderer's accepted geometry: restore the chain's
        self.state = init(self.state.params, self.posterior.face, image=True)
        return estimate_noise(target, rendered.image, rendered.mask, usable=usable)

    def set_noise(self, noise: NoiseModel) -> float:
        """Target the posterior of ``noise`` from now on (re-evaluates the current state)."""
        post = self.posterior
        self.posterior = build_posterior(self.problem, noise, renderer=post.renderer,
                                         geometry=post.geometry)
        self._gradient = None  # the gradient is of the posterior it was built for
        self._build_proposal()
        self.state = init(self.state.params, self.posterior.face, image=True)
        self._phase_start = self._warm.steps_done if self._warm is not None else 0
        return self.state.log_lik_img

    def finish(self) -> ChainResult:
        """Return the chain's records (landmark stage, warm-up, kept draws) with its seed."""
        warm = self._warm.record(self._t_warm) if self._warm is not None else None
        kept = self._kept.record(self._t_kept) if self._kept is not None else None
        if warm is not None:
            warm.extra["scales"] = dict(self.scales)
            if self.cfg.mala_weight > 0:
                warm.extra["mala_step"] = self.mala_step
                warm.extra["mala_diag"] = [float(v) for v in self.mala_diag]
        return ChainResult(self.index, int(self.seed.entropy),
                           tuple(int(k) for k in self.seed.spawn_key), self.stage1, kept, warm)

    @property
    def chain_target(self):
        """The target the chain runs on (the image stage's full posterior)."""
        return self.posterior.face


def _with_solved_light(target, params: RenderParameter, data: RenderLightData) -> RenderParameter:
    """``params`` with the least-squares SH light if it renders the target better."""
    rendered = target.init_render(params)
    normals, albedo, colours = data(ProposalState(params, rendered))
    if normals.shape[0] < 20:
        return params
    solved = params._replace(environment_map=SHLight(solve_sh_light(normals, albedo, colours)))
    before = target.log_lik_image(rendered)
    after = target.log_lik_image(target.init_render(solved))
    return solved if after > before else params
