"""A joint fit: several photographs of one face, one identity (shape and albedo), one posterior.

:func:`fit_joint` checks each photograph and its landmarks as :func:`mcmcfit.fitting.fit.fit`
does, guesses each image's pose from its landmarks, and runs the chains of a
:class:`~mcmcfit.fitting.joint_problem.JointProblem` (sessions:
:class:`~mcmcfit.fitting.joint_session.JointChainSession`) through the same
driver as a single fit (:func:`mcmcfit.fitting.driver.drive_chains`: the climb to
the mode, warm-up, kept draws until converged). The result is a
:class:`~mcmcfit.fitting.result.FitResult` whose layout is the joint one
(:class:`~mcmcfit.sampling.joint_layout.JointParamLayout`) and whose parameters
are :class:`~proposals.joint.JointParameter`.

Only the Gaussian sampler is supported (the default); a face box in place of
landmarks is not.

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.model`,
:mod:`mcmcfit.fitting` (chain_pool, config, fit, initialisation, joint_problem,
problem, result), :mod:`mcmcfit.sampling` (derived, joint_layout, param_vector),
:mod:`mcmcfit.targets.landmarks` and :mod:`proposals.joint`.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Sequence

import numpy as np
from threadpoolctl import threadpool_limits

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from mcmcfit.fitting.chain_pool import chain_pool
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.driver import Progress, drive_chains
from mcmcfit.fitting.fit import BLACK_LEVEL, assemble_result
from mcmcfit.fitting.initialisation import check_fit_inputs, initial_params, pose_from_landmarks
from mcmcfit.fitting.joint_problem import JointProblem
from mcmcfit.fitting.problem import FitProblem, landmark_factor
from mcmcfit.fitting.result import FitResult
from mcmcfit.sampling.derived import region_albedo_basis
from mcmcfit.sampling.joint_layout import JointParamLayout
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.targets.landmarks import LandmarkGeometry, LandmarkTarget
from proposals.joint import JointParameter

__all__ = ["MAX_IMAGES", "fit_joint"]

#: Photographs one joint fit takes at most (its coordinates grow by ~45 per image).
MAX_IMAGES = 8


def _image_problem(i: int, image: np.ndarray, landmarks, model: MorphableModel,
                   cfg: FitConfig, geometry: LandmarkGeometry, model_uri: str,
                   landmark_sigma) -> tuple[FitProblem, tuple[str, ...]]:
    """One photograph's problem with its pose guessed from its landmarks; the landmarks used."""
    img = np.asarray(image, np.float64)
    if img.ndim != 3 or img.shape[2] != 3:
        raise InputError(f"image {i + 1} must have shape (H, W, 3), got {img.shape}")
    if not np.all(np.isfinite(img)):
        raise InputError(f"image {i + 1} contains NaN or infinite values")
    if img.size == 0 or float(img.max()) < BLACK_LEVEL:
        raise InputError(f"image {i + 1} is entirely black: there is no face to fit")
    if landmarks is None:
        raise InputError(f"image {i + 1} has no landmarks: a joint fit needs landmarks for "
                         "every photograph")
    h, w = img.shape[:2]
    check_fit_inputs(w, h, landmarks=landmarks, face_box=None,
                     model_landmarks=model.landmark_vertices)
    params0 = initial_params(model, w, h, n_shape=cfg.n_shape, n_albedo=cfg.n_albedo,
                             n_expression=cfg.n_expression, model_uri=model_uri)
    problem = FitProblem(img, landmarks, None, landmark_sigma, model, cfg, params0,
                         ParamLayout.for_params(params0))
    factor = landmark_factor(problem, geometry)
    if not isinstance(factor, LandmarkTarget):
        raise InputError(f"image {i + 1}: its landmarks name none the model has")
    if factor.unknown:
        warnings.warn(f"image {i + 1}: ignoring {len(factor.unknown)} landmark(s) the model "
                      f"does not have: {', '.join(factor.unknown)}", stacklevel=3)
    if len(factor.names) >= 2:
        params0 = pose_from_landmarks(geometry, factor.names, factor.observed, params0,
                                      refine=cfg.init_pose == "lsq")
    return dataclasses.replace(problem, start=params0), tuple(factor.names)


def fit_joint(images: Sequence[np.ndarray], landmarks: Sequence, model: MorphableModel, *,
              config: FitConfig | None = None, seed: int = 0, progress: Progress | None = None,
              model_uri: str = "", landmark_sigma=None) -> FitResult:
    """Fit several photographs of one face: one posterior over the shared identity.

    Parameters
    ----------
    images : sequence of (H, W, 3) float arrays
        Gamma-encoded sRGB in [0, 1] (sizes may differ).
    landmarks : sequence
        Per image, its target landmarks (as :func:`mcmcfit.fitting.fit.fit` takes them).
    model : MorphableModel
    config : FitConfig, optional
        The settings of every image (the Gaussian sampler only).
    seed : int
    progress : callable, optional
        ``progress(stage, chain, done, total)``.
    model_uri : str
    landmark_sigma : optional
        As :func:`mcmcfit.fitting.fit.fit`'s, for every image.

    Returns
    -------
    FitResult
        Its ``layout`` is a :class:`~mcmcfit.sampling.joint_layout.JointParamLayout`,
        its parameters (``best.params``, ``mean_params``, ``template``)
        :class:`~proposals.joint.JointParameter`.

    Raises
    ------
    InputError
        Fewer than 2 or more than :data:`MAX_IMAGES` images, a count of
        landmark sets that differs, a bad image or landmark set (named by its
        position), a sampler other than ``"gaussian"``, or a robust foreground.
    """
    cfg = config or FitConfig()
    if cfg.foreground != "gaussian":
        raise InputError("a joint fit has the Gaussian foreground only (--foreground robust "
                         "is for single photographs)")
    if not 2 <= len(images) <= MAX_IMAGES:
        raise InputError(f"a joint fit takes 2 to {MAX_IMAGES} photographs, got {len(images)}")
    if len(landmarks) != len(images):
        raise InputError(f"{len(images)} photographs but {len(landmarks)} landmark sets")
    if cfg.sampler != "gaussian":
        raise InputError(f"a joint fit runs the Gaussian sampler only, not {cfg.sampler!r}")
    with threadpool_limits(limits=1, user_api="blas"):
        t_start = time.perf_counter()
        geometry = LandmarkGeometry(model, threads=1)
        built = [_image_problem(i, im, lm, model, cfg, geometry, model_uri, landmark_sigma)
                 for i, (im, lm) in enumerate(zip(images, landmarks))]
        problems = tuple(p for p, _ in built)
        start = JointParameter.share([p.start for p in problems])
        problem = JointProblem(problems, cfg, start, JointParamLayout.for_params(start))
        regions = region_albedo_basis(model)
        pool = chain_pool(problem, np.random.SeedSequence(seed).spawn(cfg.chains),
                          processes=cfg.parallel)
        setup_s = time.perf_counter() - t_start
        try:
            results, noise, stopping = drive_chains(pool, cfg, problem.layout, t_start,
                                                    progress, regions)
        finally:
            pool.close()
        used = tuple(sorted({n for _, names in built for n in names}))
        return assemble_result(cfg, seed, problem.layout, start, results, [start] * len(results),
                               used, (), setup_s, time.perf_counter() - t_start, noise,
                               stopping, regions)
