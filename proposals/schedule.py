"""The default proposal schedules: the reference's multi-scale mixtures, plus our additions.

Scales and weights are those of the Basel face pipeline's ``StandardFitScript``
(``reference-sampler.md`` §4, "Mixture weights"):

===========================  ==========================================================
yaw / pitch / roll           0.75 / 0.10 / 0.01 rad : 0.1 / 0.4 / 0.5; axes 0.5 / 0.3 / 0.2
translation                  300 / 50 / 10 mm : 0.2 / 0.2 / 0.6
distance                     500 / 50 / 5 mm : 0.2 / 0.6 / 0.2
focal scaling (log)          0.15 / 0.05 / 0.01 : 0.2 / 0.6 / 0.2
pose                         {rotation, distance, scaling} 1/3 each, centred at four
                             landmarks (weight 1 each), + translation 0.2
shape / albedo / expression  walks 0.2 / 0.1 / 0.025, caricature 0.2 : 0.1 / 0.5 / 0.2 / 0.2
MoMo                         (shape 1/2 + albedo 1/2) 1/2 + expression 1/2 (the image
                             stage's default: expression 1/4, see below)
colour                       gain log 0.01 / 0.001 / 0.0005 (contrast 0.01, offset 1e-4)
                             : 0.2 / 0.6 / 0.2
light                        spatial 0.05, bands 0.1, intensity 0.1 (log 0.05),
                             perturbation 0.001 (energy kept), colour 0.01: equal shares
                             of 5/6, solver 1/6 (without a solver the five share 1)
top level                    pose 1 : colour 1 : MoMo 3 : light 2 (+ specular exponent 0.1,
                             + albedo conditional / light-albedo exchange 0.25 when
                             their data are given)
===========================  ==========================================================

Differences from the reference, on purpose: every ratio is exact (see each
proposal's docstring); coefficient walks move chunks of ``block_size``
coefficients (the reference moves all at once; ``block_size=None`` restores
that); the specular exponent gets a small-weight log-normal proposal; the SH
solver is an independence proposal with a proper ratio; with albedo data the
image stage adds the albedo conditional (a Gibbs-like draw of every albedo
coefficient) and light-albedo exchanges (light intensity x albedo ridge),
both accepted by one joint MH test (:mod:`proposals.albedo_solver`).

This module imports only :mod:`albedo_model.params` and the other :mod:`proposals`
modules (albedo_solver, base, coefficients, color_transform, light, light_solver, pose).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from albedo_model.params import Block, RenderParameter
from proposals.albedo_solver import AlbedoConditional, AlbedoData, LightAlbedoExchange
from proposals.base import Mixture, mixture
from proposals.coefficients import Caricature, CoefficientWalk
from proposals.color_transform import ColorTransformWalk
from proposals.light import (
    SHBandMixer,
    SHColorShift,
    SHIntensity,
    SHPerturbation,
    SHSpatial,
    SpecularExponentScaling,
)
from proposals.light_solver import LightData, SHLightSolver
from proposals.pose import Distance, FocalScaling, ImageCentered, Rotation, Translation

__all__ = [
    "CENTERING_LANDMARKS", "LandmarkPoint", "pose_proposal", "momo_proposal",
    "color_transform_proposal", "light_proposal", "specular_exponent_proposal",
    "default_image_proposal", "landmark_stage_proposal",
]

#: ``landmark_point(name, params) -> (3,)``: a landmark's model-frame position (mm) at the
#: shape and expression of ``params``.
LandmarkPoint = Callable[[str, RenderParameter], np.ndarray]

#: The landmarks the reference's pose proposals keep fixed in the image.
CENTERING_LANDMARKS = (
    "right.eye.corner_outer", "left.eye.corner_outer", "right.lips.corner", "left.lips.corner",
)

_SCALE_WEIGHTS = (0.2, 0.6, 0.2)


def _rotation() -> Mixture:
    per_axis = []
    for axis, w_axis in (("yaw", 0.5), ("pitch", 0.3), ("roll", 0.2)):
        scales = mixture(*((w, Rotation(axis, s)) for s, w in ((0.75, 0.1), (0.10, 0.4),
                                                                 (0.01, 0.5))), name=axis)
        per_axis.append((w_axis, scales))
    return mixture(*per_axis, name="rotation")


def _translation() -> Mixture:
    return mixture(*((w, Translation(s)) for s, w in ((300.0, 0.2), (50.0, 0.2), (10.0, 0.6))),
                   name="translation")


def _moving_no_translation() -> Mixture:
    distance = mixture(*((w, Distance(s)) for s, w in zip((500.0, 50.0, 5.0), _SCALE_WEIGHTS)),
                       name="distance")
    focal = mixture(*((w, FocalScaling(s)) for s, w in zip((0.15, 0.05, 0.01), _SCALE_WEIGHTS)),
                    name="focal")
    return mixture((1.0, _rotation()), (1.0, distance), (1.0, focal), name="pose-moving")


def _anchor(landmark_point: LandmarkPoint, name: str) -> Callable[[RenderParameter], np.ndarray]:
    def anchor(params: RenderParameter) -> np.ndarray:
        return landmark_point(name, params)
    return anchor


def pose_proposal(landmark_point: LandmarkPoint | None, *,
                  landmarks: Sequence[str] = CENTERING_LANDMARKS) -> Mixture:
    """Build the reference's pose mixture (touches POSE | CAMERA).

    Parameters
    ----------
    landmark_point : callable ``(name, params) -> (3,)``, or None
        Model-frame position of a landmark at the state's shape and expression.
        None (or no ``landmarks``) uses the uncentred rotation/distance/scaling
        mixture in place of the centred copies, with their total weight.
    landmarks : sequence of str
        Landmarks to centre at, weight 1 each.

    Returns
    -------
    Mixture of ``ImageCentered(rotation | distance | scaling, lm)`` for each landmark
    (weight 1 each) and translation (weight 0.2).
    """
    inner = _moving_no_translation()
    if landmark_point is None or not landmarks:
        # same total weight as the centred copies would have (4 by default)
        moving = [(float(len(landmarks) or len(CENTERING_LANDMARKS)), inner)]
    else:
        moving = [(1.0, ImageCentered(inner, _anchor(landmark_point, lm), label=lm))
                  for lm in landmarks]
    return mixture(*moving, (0.2, _translation()), name="pose")


def _coefficient_mixture(block: Block, block_size: int | None, name: str) -> Mixture:
    walks = [(w, CoefficientWalk(block, s, block_size=block_size))
             for s, w in ((0.2, 0.1), (0.1, 0.5), (0.025, 0.2))]
    return mixture(*walks, (0.2, Caricature(block, 0.2)), name=name)


def momo_proposal(*, block_size: int | None = 10, expression_weight: float = 0.5) -> Mixture:
    """Shape, albedo (shared colour coefficients) and expression mixture.

    Parameters
    ----------
    block_size : int or None
        Coefficients moved per random-walk step (a random chunk); None moves all.

    expression_weight : float in [0, 1]
        Share of the expression moves (the reference: 1/2).

    Returns
    -------
    Mixture ``(shape 1/2 + albedo 1/2) (1 - e) + expression e`` of per-block mixtures.
    """
    shape = _coefficient_mixture(Block.SHAPE, block_size, "shape")
    albedo = _coefficient_mixture(Block.ALBEDO, block_size, "albedo")
    expression = _coefficient_mixture(Block.EXPRESSION, block_size, "expression")
    identity = mixture((0.5, shape), (0.5, albedo), name="identity")
    return mixture((1.0 - expression_weight, identity), (expression_weight, expression),
                   name="momo")


def color_transform_proposal() -> Mixture:
    """Build the colour-transform mixture (gain, contrast and offset all move)."""
    return mixture(*((w, ColorTransformWalk(g, 0.01, 1e-4))
                     for g, w in zip((0.01, 0.001, 0.0005), _SCALE_WEIGHTS)), name="color-transform")


def light_proposal(solver_data: LightData | None = None, *, solver_sigma: float = 0.005,
                   solver_ridge: float = 1e-4) -> Mixture:
    """Build the SH light mixture, with the least-squares solver when data are given.

    Parameters
    ----------
    solver_data : callable ``(params) -> (normals, albedo, target)``, optional
        See :class:`~proposals.light_solver.SHLightSolver`. Without it the five
        reference proposals share the weight equally (as in AlbedoMM).
    solver_sigma, solver_ridge : float
        Spread of the solver's independence draw and its regularisation.
    """
    five = (SHSpatial(0.05), SHBandMixer(0.1), SHIntensity(0.1 / 2),
            SHPerturbation(0.001, fix_energy=True), SHColorShift(0.01))
    parts = [(5.0 / 6.0 / 5.0, p) for p in five]
    if solver_data is not None:
        parts.append((1.0 / 6.0, SHLightSolver(solver_data, sigma=solver_sigma,
                                               ridge=solver_ridge)))
    return mixture(*parts, name="light")


def specular_exponent_proposal() -> Mixture:
    """Log-normal scalings of the specular exponent (log sigma 0.1 and 0.02, equal weights)."""
    return mixture((0.5, SpecularExponentScaling(0.1)), (0.5, SpecularExponentScaling(0.02)),
                   name="specular-exponent")


def default_image_proposal(landmark_point: LandmarkPoint | None, *,
                           solver_data: LightData | None = None, specular_weight: float = 0.1,
                           block_size: int | None = 10, solver_sigma: float = 0.005,
                           solver_ridge: float = 1e-4, albedo_data: AlbedoData | None = None,
                           albedo_weight: float = 0.25, pixel_sigma: float = 0.043,
                           expression_weight: float = 0.25) -> Mixture:
    """Build the image-stage proposal: pose 1 : colour 1 : MoMo 3 : light 2 : specular exponent.

    Parameters
    ----------
    landmark_point : callable ``(name, params) -> (3,)`` or None
        For the image-centred pose moves (see :func:`pose_proposal`).
    solver_data : callable, optional
        Data of the SH least-squares light proposal (see :func:`light_proposal`).
    specular_weight : float
        Top-level weight of the specular-exponent proposal (0 disables it, e.g.
        for a model without specular albedo).
    block_size : int or None
        Chunk size of the coefficient random walks.
    solver_sigma, solver_ridge : float
        Passed to :func:`light_proposal`.
    albedo_data : callable, optional
        Data of the albedo conditional proposal
        (:class:`~proposals.albedo_solver.AlbedoConditional`); without it the
        albedo moves only by the random walks.
    albedo_weight : float
        Top-level weight of the albedo conditional moves: half a Gibbs-like draw
        of the albedo, half light-albedo exchanges (light scale log sigma 0.1 /
        0.03, albedo redrawn under the new light).
    pixel_sigma : float
        Pixel noise of the image likelihood (for the albedo conditional).
    expression_weight : float
        Share of expression moves in the MoMo mixture. 1/4 rather than the
        reference's 1/2: the default model has 3 expression components (BFM
        has 100), and every expression move re-casts the rays.
    """
    extra = []
    if albedo_data is not None and albedo_weight > 0:
        extra.append((albedo_weight, mixture(
            (0.5, AlbedoConditional(albedo_data, sigma=pixel_sigma)),
            (0.25, LightAlbedoExchange(albedo_data, log_sigma=0.1, sigma=pixel_sigma)),
            (0.25, LightAlbedoExchange(albedo_data, log_sigma=0.03, sigma=pixel_sigma)),
            name="albedo-conditional")))
    return mixture(
        (1.0, pose_proposal(landmark_point)),
        (1.0, color_transform_proposal()),
        (3.0, momo_proposal(block_size=block_size, expression_weight=expression_weight)),
        (2.0, light_proposal(solver_data, solver_sigma=solver_sigma, solver_ridge=solver_ridge)),
        (specular_weight, specular_exponent_proposal()),
        *extra,
        name="image",
    )


def landmark_stage_proposal(landmark_point: LandmarkPoint | None, *, shape_weight: float = 0.0,
                            block_size: int | None = 10) -> Mixture:
    """Build the landmark-stage proposal: the reference's pose mixture, optionally with shape.

    Parameters
    ----------
    landmark_point : callable ``(name, params) -> (3,)`` or None
    shape_weight : float
        Weight of the shape mixture relative to the pose mixture (weight 1);
        0 (default) is the reference's pose-only landmark chain.
    block_size : int or None
        Chunk size of the shape random walks.
    """
    return mixture((1.0, pose_proposal(landmark_point)),
                   (shape_weight, _coefficient_mixture(Block.SHAPE, block_size, "shape")),
                   name="landmarks")
