"""One chain of a joint fit of several photographs of one face, in the phases of a single fit.

:class:`JointChainSession` answers the same calls as
:class:`~mcmcfit.fitting.chain_session.ChainSession` (the fit driver,
:func:`mcmcfit.fitting.driver.drive_chains`, runs it unchanged, in this process or
in worker processes), with the Gaussian sampler only:

1. ``landmarks`` -- each image's landmark stage, as a single fit's (several
   starts); the joint start takes each image's pose and the mean of their shapes;
2. ``begin_image`` -- each image's least-squares light;
3. ``climb`` / ``measure_target`` / ``set_region`` -- the climb to the joint mode
   (:func:`mcmcfit.fitting.mode.find_mode` on
   :class:`~mcmcfit.targets.joint_curvature.JointCurvature` and
   :class:`~proposals.laplace.joint_coordinates.JointCoordinates`), each image's
   pixel region and noise model measured at it;
4. ``prepare_gaussian`` -- the joint Laplace approximation and the moves: Crank-Nicolson,
   the Gaussian blocks (each block the identity's part and every image's part
   together), the whitened HMC, the albedo's exact conditional over every image
   (:class:`~proposals.joint.SharedAlbedoConditional`) and each image's SH light's
   exact conditional (lifted, :func:`~proposals.joint.lift`);
5. ``warmup`` (step sizes adapted), ``draw`` (kept draws), ``finish``.

The chain records use the joint layout (:class:`~mcmcfit.sampling.joint_layout.JointParamLayout`);
each image's landmark stage is kept in the kept record's ``extra["landmark_best"]``.

This module imports :mod:`albedo_model.params`, :mod:`mcmcfit.fitting` (adaptation,
chain_session, gaussian_stage, joint_problem, landmark_starts, mode, problem),
:mod:`mcmcfit.proposal_data`, :mod:`mcmcfit.sampling`, :mod:`mcmcfit.targets` and
:mod:`proposals`.
"""

from __future__ import annotations

import re

import numpy as np

from albedo_model.render.pixel_cast import SceneCaster
from mcmcfit.fitting.adaptation import MIN_PROPOSED, adapt_scales, family_counts
from mcmcfit.fitting.chain_session import _with_solved_light, use_compilation_cache
from mcmcfit.fitting.gaussian_stage import (
    START_ERODE, recentred, region_and_noise,
    sampling_coordinates,
)
from mcmcfit.fitting.joint_problem import JointNoise, JointProblem
from mcmcfit.fitting.landmark_starts import DEFAULT_STARTS, landmark_stage
from mcmcfit.fitting.draw_phases import DrawPhases
from mcmcfit.fitting.mode import ADOPT_GAP, POLISH_STEPS, ModeResult, find_mode, laplace, region_of
from mcmcfit.fitting.problem import build_posterior, provisional_noise
from mcmcfit.proposal_data.albedo import RenderAlbedoData
from mcmcfit.proposal_data.face_pixels import unsaturated
from mcmcfit.proposal_data.light import RenderLightData
from mcmcfit.proposal_data.light_system import RenderLightSystem
from mcmcfit.sampling.chain import ChainRecorder, ChainResult
from mcmcfit.sampling.kernel import init
from mcmcfit.targets.curvature import PosteriorCurvature
from mcmcfit.targets.joint import JointTarget
from mcmcfit.targets.joint_curvature import JointCurvature, joint_coordinate_gradient
from mcmcfit.targets.landmarks import LandmarkTarget
from proposals.joint import JointParameter, SharedAlbedoConditional, lift
from proposals.laplace.image_scale import ImageScale, anchor_vertices
from proposals.laplace.joint_coordinates import JointCoordinates
from proposals.laplace.moves import GaussianApproximation
from proposals.laplace.schedule import GAUSSIAN_BLOCKS, GAUSSIAN_TARGETS, gaussian_image_proposal
from proposals.light_conditional import LightConditional
from proposals.schedule import (
    CENTERING_LANDMARKS, FAMILIES, family_of, landmark_stage_proposal,
)

__all__ = ["JointChainSession"]

_PREFIX = re.compile(r"^image\d+\.")
_APPEARANCE = GAUSSIAN_BLOCKS["gaussian-albedo"] + GAUSSIAN_BLOCKS["gaussian-shading"]


class JointChainSession(DrawPhases):
    """One chain of a joint fit (see the module notes).

    Parameters
    ----------
    problem : JointProblem
    index : int
    seed : numpy SeedSequence
    threads : int, optional
        Ray-casting threads of each image's renderer.
    """

    def __init__(self, problem: JointProblem, index: int, seed: np.random.SeedSequence, *,
                 threads: int | None = None):
        use_compilation_cache()
        self.problem, self.index, self.seed = problem, int(index), seed
        self.cfg = problem.config
        self.rng = np.random.default_rng(seed)
        self._data_seeds = [int(x) for x in seed.generate_state(2)]
        noise = provisional_noise(self.cfg)
        self.posts = [build_posterior(p, noise, threads=threads) for p in problem.images]
        self.noise = JointNoise((noise,) * problem.n_images)
        self.regions: list[np.ndarray | None] = [None] * problem.n_images
        self.casters = [SceneCaster(problem.model) for _ in problem.images]
        self.target = self._joint_target()
        self.scales: dict[str, float] = {f: 1.0 for f in FAMILIES}
        self.coords: JointCoordinates | None = None
        self._hmc_gradient = None
        self.approx: GaussianApproximation | None = None
        self.mode: ModeResult | None = None
        self.proposal = None
        self.family: dict[str, str] = {}
        self._build_data()
        self.landmark_best: list[dict] = []
        self.start: JointParameter = problem.start
        self.state = None
        self._warm: ChainRecorder | None = None
        self._kept: ChainRecorder | None = None
        self._t_warm = self._t_kept = 0.0
        self._pending: dict[str, tuple[int, int]] = {}

    # -- targets and proposals ---------------------------------------------------------
    def _joint_target(self, posts=None) -> JointTarget:
        posts = self.posts if posts is None else posts
        return JointTarget([p.face for p in posts], posts[0].face.prior)

    def _build_data(self) -> None:
        self.albedo_data = [RenderAlbedoData(p.renderer, p.image_target.linear,
                                             n_points=self.cfg.albedo_points,
                                             seed=self._data_seeds[1], region=r)
                            for p, r in zip(self.posts, self.regions)]
        self.light_system = [RenderLightSystem(p.image_target.linear, region=r)
                             for p, r in zip(self.posts, self.regions)]

    def _curvature(self, posts=None) -> JointCurvature:
        posts = self.posts if posts is None else posts
        return JointCurvature([PosteriorCurvature(p.face, c.layout, caster=caster)
                               for p, c, caster in zip(posts, self.coords.images, self.casters)])

    def _build_proposal(self) -> None:
        cfg, n = self.cfg, self.problem.n_images
        k = self.problem.start.images[0].environment_map.coefficients.shape[0]
        mean, sd = self.posts[0].face.prior.light_gaussian(k)
        lights = [(0.5 * cfg.conditional_weight / n,
                   lift(i, LightConditional(self.light_system[i], mean, sd,
                                            sigma=self.posts[i].pixel_sigma)))
                  for i in range(n)]
        albedo = SharedAlbedoConditional(self.albedo_data, [p.pixel_sigma for p in self.posts])
        gradient = self._coordinate_gradient() if cfg.hmc_weight > 0 else None
        self.proposal = gaussian_image_proposal(
            self.coords, self.approx, scales=self.scales, pcn_weight=cfg.pcn_weight,
            block_weight=cfg.block_weight, gradient=gradient, hmc_weight=cfg.hmc_weight,
            hmc_leapfrog=cfg.hmc_leapfrog, hmc_random_steps=cfg.hmc_random_steps,
            extra_moves=[(0.5 * cfg.conditional_weight, albedo), *lights])
        self.family = family_of(self.proposal)

    # -- landmark stage and start ------------------------------------------------------
    def _coordinate_gradient(self):
        """Return the joint posterior's gradient in the coordinates (built once per posterior)."""
        if self._hmc_gradient is None:  # one per posterior and coordinates (Jacobians are big)
            curvature = self._curvature()
            triangles = (curvature.region_triangles(self.mode.params)
                         if self.cfg.hmc_triangles == "mode" else None)
            self._hmc_gradient = joint_coordinate_gradient(curvature, self.coords, triangles)
        return self._hmc_gradient

    def landmarks(self) -> float:
        """Run every image's landmark stage; the joint start takes their poses and mean shape."""
        cfg = self.cfg
        if cfg.landmark_steps == 0:
            return float("nan")
        images, total = [], 0.0
        for post, prob in zip(self.posts, self.problem.images):
            factor, geometry = post.landmarks_only.landmarks, post.geometry
            starts = DEFAULT_STARTS if isinstance(factor, LandmarkTarget) else ("guess",)
            centring = (geometry.point if all(n in geometry.names for n in CENTERING_LANDMARKS)
                        else None)
            proposal = landmark_stage_proposal(centring, shape_weight=cfg.stage1_shape_weight,
                                               block_size=cfg.block_size)
            rec, _ = landmark_stage(self.rng, prob.start, post.landmarks_only, proposal,
                                    cfg.landmark_steps, layout=prob.layout, thin=cfg.thin,
                                    starts=starts)
            best = rec.best_posterior
            images.append(best.params)
            total += float(best.log_posterior)
            self.landmark_best.append({"log_posterior": float(best.log_posterior),
                                       "yaw": float(best.params.pose.yaw)})
        shape = np.mean([np.asarray(p.momo.shape) for p in images], axis=0)
        first = images[0]._replace(momo=images[0].momo._replace(shape=shape))
        self.start = JointParameter.share([first, *images[1:]])
        return total

    def begin_image(self) -> float:
        """Start the image stage: each image's SH light solved where that renders it better."""
        images = list(self.start.images)
        if self.cfg.init_light == "solve":
            for i, post in enumerate(self.posts):
                data = RenderLightData(post.renderer, post.image_target.linear,
                                       n_points=self.cfg.solver_points,
                                       seed=self._data_seeds[0])
                images[i] = _with_solved_light(post.face, images[i], data)
        self.start = JointParameter(tuple(images))
        self.state = init(self.start, self.target, image=True)
        return self.state.log_lik_img

    # -- the climb, regions and noise ---------------------------------------------------
    def _region(self, i: int, params, erode: int | None = None) -> np.ndarray:
        erode = self.cfg.region_erode if erode is None else max(erode, self.cfg.region_erode)
        usable = unsaturated(self.posts[i].image_target.linear.reshape(-1, 3))
        return region_of(self.casters[i], params, usable, erode=erode,
                         contour_band=self.cfg.region_band)

    def _region_posts(self, regions, noise: JointNoise):
        return [build_posterior(prob, nz, renderer=post.renderer, geometry=post.geometry,
                                region=r)
                for prob, post, r, nz in zip(self.problem.images, self.posts, regions,
                                             noise.images)]

    def _climb(self, posts, params: JointParameter, steps: int, *, polish: int = 0,
               free: np.ndarray | None = None) -> ModeResult:
        target, curvature = self._joint_target(posts), self._curvature(posts)
        res = find_mode(target, curvature, self.coords, params, rng=self.rng, max_steps=steps,
                        free=free)
        if polish:
            more = find_mode(target, curvature, self.coords, res.params, rng=self.rng,
                             max_steps=polish, step_pixels=np.iinfo(np.int64).max)
            res = more._replace(iterations=res.iterations + more.iterations,
                                trace=res.trace + more.trace[1:])
        return res

    def _measure(self, params: JointParameter) -> tuple[tuple, JointNoise]:
        regions = tuple(self._region(i, p) for i, p in enumerate(params.images))
        if self.cfg.noise != "estimated":
            return regions, JointNoise((provisional_noise(self.cfg),) * len(regions))
        return regions, JointNoise(tuple(
            region_and_noise(post.renderer, post.image_target.linear, p, r)
            for post, p, r in zip(self.posts, params.images, regions)))

    def climb(self) -> dict:
        """Climb to the joint mode: the appearance first, then everything (as a single fit)."""
        cfg = self.cfg
        start = JointParameter.share([recentred(p) for p in self.state.params.images])
        self.coords = JointCoordinates([sampling_coordinates(p) for p in start.images])
        noise = JointNoise((provisional_noise(cfg),) * self.problem.n_images)
        regions = tuple(self._region(i, p, erode=START_ERODE) for i, p in enumerate(start.images))
        free = np.array([_PREFIX.sub("", n).startswith(_APPEARANCE) for n in self.coords.names])
        res = self._climb(self._region_posts(regions, noise), start, cfg.mode_steps, free=free)
        params, traces = res.params, [list(res.trace)]
        for i in range(max(1, cfg.mode_rounds)):
            if i > 0 and cfg.noise != "estimated":
                regions = self._measure(params)[0]
            res = self._climb(self._region_posts(regions, noise), params, cfg.mode_steps)
            params = res.params
            traces.append(list(res.trace))
            if cfg.noise == "estimated":
                regions, noise = self._measure(params)
        self.mode = res._replace(params=params)
        score = init(params, self.target, image=True).log_posterior
        self.state = init(self.state.params, self.target, image=True)
        return {"score": float(score), "trace": traces}

    def choose_effects(self) -> dict:
        """Return the decision "sh": a joint fit has the SH light alone (no directional light)."""
        return {"decision": "sh", "reason": "a joint fit models the SH light only"}

    def set_effects(self, decision: str) -> bool:
        """Keep the SH light alone (see :meth:`choose_effects`); return False."""
        return False

    def mode_params(self) -> JointParameter:
        """Return the mode the last climb reached."""
        return self.mode.params

    def measure_target(self) -> tuple[tuple, JointNoise]:
        """Return every image's region and noise model measured at this chain's mode."""
        return self._measure(self.mode.params)

    def set_region(self, regions, noise: JointNoise, best: JointParameter | None = None) -> float:
        """Target the posterior over the fixed regions at ``noise`` and climb to its mode."""
        self.regions = [np.asarray(r, bool) for r in regions]
        self.noise = noise
        self.posts = self._region_posts(self.regions, noise)
        self.target = self._joint_target()
        self._hmc_gradient = None  # a function of the posterior just replaced
        self._build_data()
        start = self.mode.params
        if best is not None:
            own = init(start, self.target, image=True).log_posterior
            if init(best, self.target, image=True).log_posterior > own + ADOPT_GAP:
                start = best
        self.mode = self._climb(self.posts, start, self.cfg.mode_steps, polish=POLISH_STEPS)
        self.state = init(self.mode.params, self.target, image=True)
        return float(self.mode.log_density)

    def prepare_gaussian(self) -> dict:
        """Fit the joint Laplace approximation, build the moves, start from a draw of it."""
        self._approximate()
        mode = self.mode.params
        start = self.coords.params_of(self.approx.draw(self.rng), mode)
        self.state = init(start, self.target, image=True)
        if not np.isfinite(self.state.log_posterior):
            self.state = init(mode, self.target, image=True)
        return {"log_density": float(self.state.log_posterior), "dimension": self.coords.size}

    def _climb_posterior(self):
        return self.posts

    def _approximate(self) -> None:
        """Set the joint coordinates, the Laplace approximation and the moves at ``self.mode``."""
        mode = self.mode.params
        if self.cfg.image_size and not mode.images[0].camera.orthographic:
            images = []
            for i, p in enumerate(mode.images):
                cur = PosteriorCurvature(self.posts[i].face, self.coords.images[i].layout,
                                         caster=self.casters[i])
                anchors = anchor_vertices(self.problem.model.triangles, cur.region_triangles(p))
                images.append(sampling_coordinates(
                    p, scale=ImageScale.of_model(self.problem.model, p, anchors),
                    inverse_distance=self.cfg.inverse_distance))
            self.coords = JointCoordinates(images)
        self._hmc_gradient = None
        self.approx = laplace(self._curvature(), self.coords, mode)
        self._build_proposal()

    # -- warm-up, draws, widening ------------------------------------------------------
    def warmup(self, n_steps: int, *, window: int, adapt: bool = True) -> dict[str, float]:
        """Run ``n_steps`` warm-up steps in windows, adapting the step sizes after each."""
        if self._warm is None:
            self._warm = ChainRecorder(self.problem.layout, 0, self.cfg.thin, self.state,
                                       stage="warmup")
        done = 0
        while done < n_steps:
            n = min(window, n_steps - done)
            first = self._warm.steps_done
            self._advance(self._warm, n)
            if adapt:
                for fam, (n_prop, n_acc) in family_counts(*self._warm.proposals_since(first),
                                                          self.family).items():
                    p0, a0 = self._pending.get(fam, (0, 0))
                    self._pending[fam] = (p0 + n_prop, a0 + n_acc)
                new = adapt_scales(self.scales, self._pending, families=FAMILIES,
                                   targets=GAUSSIAN_TARGETS)
                for fam in FAMILIES:
                    if self._pending.get(fam, (0, 0))[0] >= MIN_PROPOSED:
                        self._pending.pop(fam)
                if new != self.scales:
                    self.scales = new
                    self._build_proposal()
            done += n
        return dict(self.scales)

    def finish(self) -> ChainResult:
        """Return the chain's records (warm-up, kept draws; the landmark stages in ``extra``)."""
        warm = self._warm.record(self._t_warm) if self._warm is not None else None
        kept = self._kept.record(self._t_kept) if self._kept is not None else None
        if warm is not None:
            warm.extra["scales"] = dict(self.scales)
        if kept is not None:
            kept.extra["landmark_best"] = list(self.landmark_best)
            kept.extra["noise"] = self.noise.to_dict()
        return ChainResult(self.index, int(self.seed.entropy),
                           tuple(int(k) for k in self.seed.spawn_key), None, kept, warm)

    @property
    def chain_target(self) -> JointTarget:
        """The target the chain runs on (the joint posterior)."""
        return self.target

    def _check(self) -> None:
        """No cache check for joint fits (``--check-cache`` checks single fits)."""
        return None
