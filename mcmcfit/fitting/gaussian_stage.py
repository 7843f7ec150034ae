"""The Gaussian sampler's preparation: climb to the mode, fix the region and noise, Laplace.

:class:`GaussianPhases` holds the phases a chain runs before the Gaussian
sampler's warm-up (:class:`~mcmcfit.fitting.chain_session.ChainSession` has
them; the driver, :mod:`mcmcfit.fitting.driver`, calls them in lockstep):

1. :meth:`~GaussianPhases.climb` -- Levenberg-Marquardt to the mode
   (:mod:`mcmcfit.fitting.mode`) from the landmark fit: first the appearance
   (:func:`appearance_coordinates`; geometry, colour transform held), then all,
   with the pixel region and the noise model re-chosen where each climb ends;
2. :meth:`~GaussianPhases.measure_target` / :meth:`~GaussianPhases.set_region` --
   the driver takes the region and noise model of the best chain's mode and
   sets them on every chain (one posterior for all), which climb again;
3. :meth:`~GaussianPhases.prepare_gaussian` -- the sampling coordinates
   (with ``image_size``: the face's log image size in place of the log focal
   length, anchored at the vertices the region sees at the mode), the Laplace
   approximation at the mode (with ``metric="hessian"`` widened where the
   posterior's curvature is flatter: :mod:`mcmcfit.fitting.curvature_widening`),
   the moves built on it, the chain started from a draw of it;
4. during the warm-up (:class:`~mcmcfit.fitting.draw_phases.DrawPhases`),
   :meth:`~GaussianPhases.recentre` -- a chain whose best warm-up draw beats its
   mode by more than :data:`~mcmcfit.fitting.mode.ADOPT_GAP` climbs again from it
   and refits the approximation there (:meth:`~GaussianPhases._approximate`); and
   optionally (``widen``) :meth:`~GaussianPhases.warmup_draws` and
   :meth:`~GaussianPhases.widen` -- the approximation widened where the
   chains' warm-up draws are wider (:mod:`proposals.laplace.widening`).

Helpers:

* :func:`recentred` centres a landmark fit's principal point (the Gaussian moves hold it).
* :func:`sampling_coordinates` are the Gaussian moves' coordinates of a fit.
* :func:`region_and_noise` measures the likelihood's scale over a pixel region
  at some parameters (:func:`mcmcfit.targets.noise_model.estimate_noise` on the
  region's residuals).

This module imports :mod:`albedo_model` (camera, params, scene_vector, render),
:mod:`mcmcfit.fitting` (curvature_widening, draw_phases, mode, problem),
:mod:`mcmcfit.proposal_data.face_pixels`,
:mod:`mcmcfit.sampling.kernel`, :mod:`mcmcfit.targets` (background, curvature, noise_model) and
:mod:`proposals.laplace` (coordinates, image_scale, schedule).
"""

from __future__ import annotations

import numpy as np

from albedo_model.camera import pixel_scale, to_eye
from albedo_model.params import RenderParameter
from albedo_model.render.renderer import Renderer
from albedo_model.scene_vector import SceneLayout
from mcmcfit.fitting.curvature_widening import curvature_widened, gradient_in_coordinates
from mcmcfit.fitting.draw_phases import DrawPhases
from mcmcfit.fitting.mode import ADOPT_GAP, POLISH_STEPS, ModeResult, find_mode, laplace, region_of
from mcmcfit.fitting.problem import build_posterior, provisional_noise
from mcmcfit.proposal_data.face_pixels import unsaturated
from mcmcfit.sampling.kernel import init
from mcmcfit.targets.background import occluder_log_density
from mcmcfit.targets.curvature import PosteriorCurvature, SceneCaster, coordinate_gradient
from mcmcfit.targets.noise_model import NoiseModel, estimate_noise
from proposals.laplace.coordinates import SamplingCoordinates
from proposals.laplace.schedule import GAUSSIAN_BLOCKS
from proposals.laplace.image_scale import ImageScale, anchor_vertices

__all__ = ["START_ERODE", "GaussianPhases", "appearance_coordinates",
           "recentred", "region_and_noise", "sampling_coordinates"]

#: Pixels the first climbs' region keeps inside the landmark fit's outline (a few px off at 250^2).
START_ERODE = 8


def recentred(params: RenderParameter) -> RenderParameter:
    """Return ``params`` with the principal point at the image centre, the face kept in place.

    The translation moves by the principal point's shift at the model origin's depth (exact
    there; elsewhere a sub-pixel perspective effect at portrait distances, which the climb absorbs).
    """
    pp_x, pp_y = params.camera.principal_point
    if pp_x == 0.0 and pp_y == 0.0:
        return params
    w, h = float(params.image_size.width), float(params.image_size.height)
    fx, fy = pixel_scale(params.camera, params.image_size)
    depth = float(-to_eye(np.zeros((1, 3)), params.pose, params.view)[0, 2])
    dx = 0.5 * w * pp_x * depth / fx
    dy = 0.5 * h * pp_y * depth / fy
    tx, ty, tz = params.pose.translation
    return params._replace(pose=params.pose._replace(translation=(tx + dx, ty + dy, tz)),
                           camera=params.camera._replace(principal_point=(0.0, 0.0)))


def appearance_coordinates(coords: SamplingCoordinates) -> np.ndarray:
    """Return the (d,) mask of the first climb's coordinates: albedo, light, specular exponent.

    The colour transform stays at the landmark fit's (identity) until the joint climbs:
    freed from the mean albedo it can reach contrast ~0 (a grey face) under a coloured
    light, a far local mode (`mcmcfit demo --seed 2`: residual RMS 0.096 against 0.005).
    """
    blocks = GAUSSIAN_BLOCKS["gaussian-albedo"] + GAUSSIAN_BLOCKS["gaussian-shading"]
    held = ("gain", "contrast", "offset")
    return np.array([n.startswith(blocks) and not n.startswith(held) for n in coords.names])


def sampling_coordinates(params: RenderParameter, scale: ImageScale | None = None, *,
                         inverse_distance: bool = False) -> SamplingCoordinates:
    """Return the Gaussian moves' coordinates for a fit whose parameters look like ``params``.

    Coordinates: the face's log image size for the focal length with ``scale``, ``d_0 / d``
    for the distance with ``inverse_distance`` (:mod:`proposals.laplace.coordinates`).
    """
    layout = SceneLayout.for_params(params)
    return SamplingCoordinates(layout, params, scale=scale, inverse_distance=inverse_distance)


def region_and_noise(renderer: Renderer, target_linear: np.ndarray, params: RenderParameter,
                     region: np.ndarray, background: np.ndarray | None = None) -> NoiseModel:
    """Return the noise model measured over ``region`` (H W,) on the render of ``params``.

    ``sigma`` is the RMS residual over the region's pixels and channels, the
    temperature their residuals' correlation area (pixels per independent
    residual); ``n_face`` counts the region's pixels. With ``background`` (an
    (H, W) occluder log density) the foreground is robust: sigma and the
    occlusion prior by EM (:func:`~mcmcfit.targets.noise_model.robust_noise`).
    """
    rendered = renderer.render(params)
    h, w = target_linear.shape[:2]
    mask = np.asarray(region, bool).reshape(h, w)
    bg = None if background is None else np.asarray(background, np.float64).reshape(h, w)
    return estimate_noise(np.asarray(target_linear), rendered.image, mask, background=bg)


class GaussianPhases(DrawPhases):
    """The Gaussian sampler's phases of a chain (a mixin of :class:`~mcmcfit.fitting.chain_session.ChainSession`).

    Reads the session's ``problem``, ``cfg``, ``rng``, ``posterior`` and
    ``state``, and sets ``coords``, ``mode``, ``region``, ``approx`` (and
    ``posterior``, ``state``); ``_warm``, ``_build_data`` and ``_build_proposal``
    are the session's.
    """

    def _scene_caster(self) -> SceneCaster:
        if self._caster is None:
            self._caster = SceneCaster(self.problem.model)
        return self._caster

    def _usable(self) -> np.ndarray:
        return unsaturated(self.posterior.image_target.linear.reshape(-1, 3))

    def _region_posterior(self, region: np.ndarray, noise: NoiseModel):
        return build_posterior(self.problem, noise, renderer=self.posterior.renderer,
                               geometry=self.posterior.geometry, region=region)

    def _climb(self, post, params: RenderParameter, steps: int, *,
               polish: int = 0, free: np.ndarray | None = None) -> ModeResult:
        curvature = PosteriorCurvature(post.face, self.coords.layout,
                                       caster=self._scene_caster())
        gradient = coordinate_gradient(curvature, self.coords)
        res = find_mode(post.face, curvature, self.coords, params, rng=self.rng,
                        max_steps=steps, free=free, gradient=gradient)
        if polish:
            more = find_mode(post.face, curvature, self.coords, res.params, rng=self.rng,
                             max_steps=polish, step_pixels=np.iinfo(np.int64).max)
            res = more._replace(iterations=res.iterations + more.iterations,
                                trace=res.trace + more.trace[1:])
        return res

    def climb(self) -> dict:
        """Climb from the image stage's start to the posterior mode (the Gaussian sampler's first phase).

        ``mode_rounds`` climbs of at most ``mode_steps`` Levenberg-Marquardt
        steps, each under the interior region of the render where the last one
        ended and (after the first, under the provisional scale) the noise
        model measured there. The chain's own state is not changed.

        Returns
        -------
        dict
            ``score``: the mode's log posterior under the likelihood over the
            render's pixels at the provisional scale (the same function for
            every chain, so the driver can pick the best mode); ``trace``: the
            log densities of the climbs.
        """
        cfg = self.cfg
        start = recentred(self.state.params)
        self.coords = sampling_coordinates(start)
        params, noise, traces = start, provisional_noise(cfg), []
        # The appearance first (geometry and colour transform held): from the mean albedo a joint
        # step trades geometry for colour and can end in a far local mode. The first climbs read
        # pixels well inside the landmark fit's outline (a pixel the true face does not cover
        # pulls the geometry to cover it); the region is reused until the geometry moves.
        region = self._region(params, erode=START_ERODE)
        res = self._climb(self._region_posterior(region, noise), params, cfg.mode_steps,
                          free=appearance_coordinates(self.coords))
        params = res.params
        traces.append(list(res.trace))
        for i in range(max(1, cfg.mode_rounds)):
            if i > 0 and cfg.noise != "estimated":
                region = self._region(params)
            res = self._climb(self._region_posterior(region, noise), params, cfg.mode_steps)
            params = res.params
            traces.append(list(res.trace))
            if cfg.noise == "estimated":
                region, noise = self._measure(params)
        self.mode = res._replace(params=params)
        score = init(params, self.posterior.face, image=True).log_posterior
        self.state = init(self.state.params, self.posterior.face, image=True)
        return {"score": float(score), "trace": traces}

    def _region(self, params: RenderParameter, erode: int | None = None) -> np.ndarray:
        erode = self.cfg.region_erode if erode is None else max(erode, self.cfg.region_erode)
        return region_of(self._scene_caster(), params, self._usable(),
                         erode=erode, contour_band=self.cfg.region_band)

    def _measure(self, params: RenderParameter) -> tuple[np.ndarray, NoiseModel]:
        region = self._region(params)
        if self.cfg.noise != "estimated":
            return region, provisional_noise(self.cfg)
        occluder = None
        if self.cfg.foreground == "robust":  # the colours outside the region
            target = self.posterior.image_target
            occluder = occluder_log_density(
                target.linear, ~np.asarray(region, bool), bins=self.cfg.bins,
                sigma=self.posterior.noise.sigma if self.cfg.background == "smoothed" else None)
        return region, region_and_noise(self.posterior.renderer,
                                        self.posterior.image_target.linear, params, region,
                                        occluder)

    def mode_params(self) -> RenderParameter:
        """Return the mode the last climb reached."""
        return self.mode.params

    def measure_target(self) -> tuple[np.ndarray, NoiseModel]:
        """Return the region and the noise model measured at this chain's mode.

        With ``noise="fixed"`` the noise model is the configured one.
        """
        return self._measure(self.mode.params)

    def set_region(self, region: np.ndarray, noise: NoiseModel,
                   best: RenderParameter | None = None) -> float:
        """Target the posterior over the fixed ``region`` at ``noise``, and climb to its mode.

        The climb starts from this chain's mode, or from ``best`` (another
        chain's) when that is higher under the new posterior by more than
        :data:`ADOPT_GAP` (a chain stuck on a far lower local mode holds
        no posterior mass worth exploring).

        Returns
        -------
        float
            The log density at the mode reached.
        """
        self.region = np.asarray(region, bool)
        self.posterior = self._region_posterior(self.region, noise)
        self._hmc_gradient = None  # a function of the posterior just replaced
        self._build_data()
        start = self.mode.params
        if best is not None:
            face = self.posterior.face
            own = init(start, face, image=True).log_posterior
            other = init(best, face, image=True).log_posterior
            if other > own + ADOPT_GAP:
                start = best
        self.mode = self._climb(self.posterior, start, self.cfg.mode_steps,
                                polish=POLISH_STEPS)
        self.state = init(self.mode.params, self.posterior.face, image=True)
        return float(self.mode.log_density)

    def prepare_gaussian(self) -> dict:
        """Fit the Laplace approximation at the mode, build the moves, start from a draw of it.

        With ``sampler="reference"`` the random-walk schedule starts from the mode instead.
        Returns ``log_density`` of the start, ``dimension`` and ``metric`` (the widening's record).
        """
        if self.cfg.sampler == "reference":  # the random walks from the mode, no approximation
            self._build_proposal()
            self.state = init(self.mode.params, self.posterior.face, image=True)
            return {"log_density": float(self.state.log_posterior),
                    "dimension": self.coords.size}
        metric = self._approximate()
        mode = self.mode.params
        start = self.coords.params_of(self.approx.draw(self.rng), mode)
        self.state = init(start, self.posterior.face, image=True)
        if not np.isfinite(self.state.log_posterior):
            self.state = init(mode, self.posterior.face, image=True)
        return {"log_density": float(self.state.log_posterior), "dimension": self.coords.size,
                "metric": metric}

    def _climb_posterior(self):
        return self.posterior

    def _approximate(self) -> dict | None:
        """Set the coordinates, Laplace approximation and moves at the mode; return the metric."""
        curvature = PosteriorCurvature(self.posterior.face, self.coords.layout,
                                       caster=self._scene_caster())
        mode = self.mode.params
        if self.cfg.image_size and not mode.camera.orthographic:
            anchors = anchor_vertices(self.problem.model.triangles,
                                      curvature.region_triangles(mode))
            scale = ImageScale.of_model(self.problem.model, mode, anchors)
            self.coords = sampling_coordinates(mode, scale,
                                               inverse_distance=self.cfg.inverse_distance)
            self._hmc_gradient = None  # a function of the coordinates just replaced
        self.approx = laplace(curvature, self.coords, mode)
        metric = None
        if self.cfg.metric == "hessian":
            self.approx, metric = curvature_widened(
                gradient_in_coordinates(self._coordinate_gradient(), self.coords, mode),
                self.approx, self.coords.u_of(mode))
        self._build_proposal()
        return metric
