"""What every chain of one fit shares, and the posterior each chain builds from it.

A :class:`FitProblem` is plain data (the image, the landmarks, the model, the
settings, the start): it is what a worker process receives. :func:`build_posterior`
turns it into the sampler's targets for one chain and one noise model
(:class:`~mcmcfit.targets.noise_model.NoiseModel`): its own renderer (one
ray-casting thread per chain when chains run in processes), the image
likelihood at the noise model's scale, the landmark or face-box factor and the
prior. The target image is compared in the model's colour space
(:func:`comparison_colour`): linearised for a linear-albedo model, as encoded
for a model whose colour is an sRGB texture.

This module imports :mod:`albedo_model` (model, params, render.renderer, io.colour_space),
:mod:`mcmcfit.fitting.config` and :mod:`mcmcfit.targets` (face, image,
landmarks, noise_model, priors).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from albedo_model.io.colour_space import model_colour_space
from albedo_model.model import MorphableModel
from albedo_model.params import ImageSize, RenderParameter
from albedo_model.render.renderer import Renderer
from mcmcfit.fitting.config import FitConfig
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.targets.background import occluder_log_density
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.image import ImageLikelihood, ImageTarget, prepare_image_target
from mcmcfit.targets.landmarks import FaceBoxTarget, LandmarkGeometry, LandmarkTarget
from mcmcfit.targets.noise_model import NoiseModel, fixed_noise
from mcmcfit.targets.priors import LogPrior

__all__ = ["FitProblem", "Posterior", "build_posterior", "fit_renderer", "comparison_colour", "landmark_factor",
           "provisional_noise"]


@dataclass(frozen=True)
class FitProblem:
    """The data and settings of one fit, shared by its chains (picklable).

    Attributes
    ----------
    image : (H, W, 3) float64, gamma-encoded sRGB in [0, 1]
    landmarks : list of Landmark, mapping, or None
    face_box : (x0, y0, x1, y1) or None
    landmark_sigma : mapping name -> float, or None
    model : MorphableModel
    config : FitConfig
    start : RenderParameter
        The pose guess with zero coefficients (the fit's template).
    layout : ParamLayout
    """

    image: np.ndarray
    landmarks: object
    face_box: tuple | None
    landmark_sigma: dict | None
    model: MorphableModel
    config: FitConfig
    start: RenderParameter
    layout: ParamLayout


def comparison_colour(problem: FitProblem) -> str:
    """Return ``"linear"`` or ``"srgb"``: the model's colour space, which the image is compared in.

    ``config.model_colour`` when set, else what the model says
    (:func:`albedo_model.io.colour_space.model_colour_space`).
    """
    return model_colour_space(problem.model, problem.config.model_colour).value


def provisional_noise(cfg: FitConfig) -> NoiseModel:
    """Return the noise model of the landmark stage and the first warm-up phase (the configured one)."""
    return fixed_noise(cfg.sigma_px, cfg.temperature,
                       cfg.outlier_probability if cfg.foreground == "robust" else 0.0)


def landmark_factor(problem: FitProblem, geometry: LandmarkGeometry):
    """Return the landmark (or face-box) factor of the problem, or None."""
    cfg = problem.config
    h, w = problem.image.shape[:2]
    if problem.landmarks is not None:
        return LandmarkTarget(geometry, problem.landmarks, sigma=cfg.sigma_lm,
                              image_size=ImageSize(w, h),
                              hidden_probability=cfg.lm_hidden_probability,
                              sigma_factors=problem.landmark_sigma)
    if problem.face_box is not None:
        return FaceBoxTarget(geometry, problem.face_box, scale_log_sigma=cfg.face_box_scale_sigma,
                             centre_sigma=cfg.face_box_centre_sigma)
    return None


@dataclass
class Posterior:
    """The targets of one chain under one noise model.

    Attributes
    ----------
    renderer : Renderer
    image_target : ImageTarget
    noise : NoiseModel
    face : FaceTarget
        The full posterior (image stage).
    landmarks_only : FaceTarget
        Prior x landmarks (landmark stage).
    geometry : LandmarkGeometry
    """

    renderer: Renderer
    image_target: ImageTarget
    noise: NoiseModel
    face: FaceTarget
    landmarks_only: FaceTarget
    geometry: LandmarkGeometry

    @property
    def pixel_sigma(self) -> float:
        """The tempered likelihood's effective per-pixel sd, ``sigma sqrt(T)`` (for the conditionals)."""
        return self.noise.sigma * math.sqrt(self.noise.temperature)


def fit_renderer(model, cfg, *, threads: int | None = None) -> Renderer:
    """Return a renderer with a fit's image model: cast shadows unless ``effects="sh"``.

    The directional light's Blinn-Phong term is scaled by the specular albedo,
    so that the render stays linear in the albedo coefficients. Shadows are
    cast only while the scene's directional light is on, with ``cfg.shadow_rays``
    rays per pixel.
    """
    return Renderer(model, specular=cfg.specular, shadows=cfg.effects != "sh",
                    directional_specular_map=True, threads=threads,
                    shadow_rays=cfg.shadow_rays, shadow_spread_deg=cfg.shadow_spread_deg)


def build_posterior(problem: FitProblem, noise: NoiseModel, *, threads: int | None = None,
                    renderer: Renderer | None = None,
                    geometry: LandmarkGeometry | None = None,
                    region: np.ndarray | None = None) -> Posterior:
    """Build one chain's targets for ``noise`` (reusing ``renderer`` and ``geometry`` if given).

    Parameters
    ----------
    problem : FitProblem
    noise : NoiseModel
        Scale of the image likelihood; the background density is smoothed with
        the same sigma (``background="smoothed"``).
    threads : int, optional
        Ray-casting threads of a new renderer (default: the config's).
    renderer, geometry : optional
        Reused when the noise model changes during warm-up.
    region : (H W,) bool, optional
        A fixed pixel region: the image likelihood is then the Gaussian over
        exactly these pixels (:class:`~mcmcfit.targets.image.ImageLikelihood`),
        whatever ``config.likelihood`` says.
    """
    cfg = problem.config
    if renderer is None:
        renderer = fit_renderer(problem.model, cfg,
                                threads=cfg.threads if threads is None else threads)
    if geometry is None:
        geometry = LandmarkGeometry(problem.model, threads=1)
    smooth = noise.sigma if cfg.background == "smoothed" else None
    target = prepare_image_target(problem.image, bins=cfg.bins, smooth_sigma=smooth,
                                  colour=comparison_colour(problem),
                                  sensor_sigma=noise.sensor_sigma)
    robust = region is not None and np.any(np.asarray(noise.outlier_prior) > 0.0)
    occluder = occluder_log_density(target.linear, ~np.asarray(region, bool), bins=cfg.bins,
                                    sigma=smooth) if robust else None
    lik = ImageLikelihood(target, kind="independent" if region is not None else cfg.likelihood,
                          sigma=noise.sigma, trim_fraction=cfg.trim_fraction,
                          temperature=max(1.0, noise.temperature), region=region,
                          background=renderer.background,
                          outlier_probability=noise.outlier_prior if robust else 0.0,
                          occluder=None if occluder is None else occluder.reshape(-1))
    factor = landmark_factor(problem, geometry)
    prior = LogPrior(cfg.prior)
    return Posterior(renderer, target, noise, FaceTarget(renderer, lik, factor, prior),
                     FaceTarget(renderer, None, factor, prior), geometry)
