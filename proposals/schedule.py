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
                             : 0.2 / 0.6 / 0.2 (70 % of the mixture; 30 %: our gain-light
                             exchange, log sigma 0.02)
light                        spatial 0.05, bands 0.1, intensity 0.1 (log 0.05),
                             perturbation 0.001 (energy kept), colour 0.01: equal shares
                             of 5/6, solver 1/6 (without a solver the five share 1)
top level                    pose 1 : colour 1 : MoMo 3 : light 2 (+ specular exponent 0.1,
                             + albedo conditional / light-albedo exchange 0.25 and the
                             SH light conditional 0.5 when their data are given, + the
                             gradient moves when asked for)
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
modules (albedo_solver, base, coefficients, color_transform, light, light_conditional,
light_solver, pose).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from albedo_model.params import Block, RenderParameter
from proposals.albedo_solver import AlbedoConditional, AlbedoData, LightAlbedoExchange
from proposals.base import Mixture, Proposal, mixture
from proposals.coefficients import Caricature, CoefficientWalk
from proposals.color_transform import ColorTransformWalk, GainLightExchange
from proposals.light_conditional import LightConditional
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
    "CENTERING_LANDMARKS", "FAMILIES", "Scales", "family_of", "LandmarkPoint", "pose_proposal", "momo_proposal",
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


#: Families of the image-stage proposals whose step sizes warm-up adapts (one
#: multiplier each, :data:`Scales`); the data-driven draws have no step size.
FAMILIES = ("yaw", "pitch", "roll", "translation", "distance", "focal", "shape", "albedo",
            "expression", "color-transform", "light", "specular-exponent",
            "pcn", "gaussian-geometry", "gaussian-albedo", "gaussian-shading",
            "geometry-walk", "geometry-wide", "hmc", "contrast-exchange", "contrast-light")


#: ``{family: multiplier}`` of every step size of a family (missing: 1). Proposal
#: names keep the reference scale (``"yaw-0.1"`` whatever its multiplier), so that
#: acceptance statistics stay comparable across warm-up windows.
Scales = Mapping[str, float]


def _rotation(k: Scales) -> Mixture:
    per_axis = []
    for axis, w_axis in (("yaw", 0.5), ("pitch", 0.3), ("roll", 0.2)):
        f = k.get(axis, 1.0)
        scales = mixture(*((w, Rotation(axis, s * f, name=f"{axis}-{s:g}"))
                           for s, w in ((0.75, 0.1), (0.10, 0.4), (0.01, 0.5))), name=axis)
        per_axis.append((w_axis, scales))
    return mixture(*per_axis, name="rotation")


def _translation(k: Scales) -> Mixture:
    f = k.get("translation", 1.0)
    return mixture(*((w, Translation(s * f, name=f"translation-{s:g}"))
                     for s, w in ((300.0, 0.2), (50.0, 0.2), (10.0, 0.6))), name="translation")


def _moving_no_translation(k: Scales) -> Mixture:
    fd, ff = k.get("distance", 1.0), k.get("focal", 1.0)
    distance = mixture(*((w, Distance(s * fd, name=f"distance-{s:g}"))
                         for s, w in zip((500.0, 50.0, 5.0), _SCALE_WEIGHTS)), name="distance")
    focal = mixture(*((w, FocalScaling(s * ff, name=f"focal-{s:g}"))
                      for s, w in zip((0.15, 0.05, 0.01), _SCALE_WEIGHTS)), name="focal")
    return mixture((1.0, _rotation(k)), (1.0, distance), (1.0, focal), name="pose-moving")


def _anchor(landmark_point: LandmarkPoint, name: str) -> Callable[[RenderParameter], np.ndarray]:
    def anchor(params: RenderParameter) -> np.ndarray:
        return landmark_point(name, params)
    return anchor


def pose_proposal(landmark_point: LandmarkPoint | None, *,
                  landmarks: Sequence[str] = CENTERING_LANDMARKS,
                  scales: Scales | None = None) -> Mixture:
    """Build the reference's pose mixture (touches POSE | CAMERA).

    Parameters
    ----------
    landmark_point : callable ``(name, params) -> (3,)``, or None
        Model-frame position of a landmark at the state's shape and expression.
        None (or no ``landmarks``) uses the uncentred rotation/distance/scaling
        mixture in place of the centred copies, with their total weight.
    landmarks : sequence of str
        Landmarks to centre at, weight 1 each.
    scales : Scales, optional
        Step-size multipliers of ``"yaw"``, ``"pitch"``, ``"roll"``,
        ``"translation"``, ``"distance"``, ``"focal"``.

    Returns
    -------
    Mixture of ``ImageCentered(rotation | distance | scaling, lm)`` for each landmark
    (weight 1 each) and translation (weight 0.2).
    """
    k = dict(scales or {})
    inner = _moving_no_translation(k)
    if landmark_point is None or not landmarks:
        # same total weight as the centred copies would have (4 by default)
        moving = [(float(len(landmarks) or len(CENTERING_LANDMARKS)), inner)]
    else:
        moving = [(1.0, ImageCentered(inner, _anchor(landmark_point, lm), label=lm))
                  for lm in landmarks]
    return mixture(*moving, (0.2, _translation(k)), name="pose")


def _coefficient_mixture(block: Block, block_size: int | None, name: str,
                         k: float = 1.0) -> Mixture:
    walks = [(w, CoefficientWalk(block, s * k, block_size=block_size, name=f"{name}-{s:g}"))
             for s, w in ((0.2, 0.1), (0.1, 0.5), (0.025, 0.2))]
    return mixture(*walks, (0.2, Caricature(block, 0.2 * k, name=f"{name}-caricature-0.2")),
                   name=name)


def momo_proposal(*, block_size: int | None = 10, expression_weight: float = 0.5,
                  scales: Scales | None = None) -> Mixture:
    """Shape, albedo (shared colour coefficients) and expression mixture.

    Parameters
    ----------
    block_size : int or None
        Coefficients moved per random-walk step (a random chunk); None moves all.

    expression_weight : float in [0, 1]
        Share of the expression moves (the reference: 1/2).
    scales : Scales, optional
        Step-size multipliers of ``"shape"``, ``"albedo"``, ``"expression"``.

    Returns
    -------
    Mixture ``(shape 1/2 + albedo 1/2) (1 - e) + expression e`` of per-block mixtures.
    """
    k = dict(scales or {})
    shape = _coefficient_mixture(Block.SHAPE, block_size, "shape", k.get("shape", 1.0))
    albedo = _coefficient_mixture(Block.ALBEDO, block_size, "albedo", k.get("albedo", 1.0))
    expression = _coefficient_mixture(Block.EXPRESSION, block_size, "expression",
                                      k.get("expression", 1.0))
    identity = mixture((0.5, shape), (0.5, albedo), name="identity")
    return mixture((1.0 - expression_weight, identity), (expression_weight, expression),
                   name="momo")


def color_transform_proposal(scale: float = 1.0, *, exchange_weight: float = 0.0) -> Mixture:
    """Build the colour-transform mixture (gain, contrast and offset all move; ``scale`` x steps).

    ``exchange_weight`` adds gain-light exchanges (log sigma 0.02 x ``scale``)
    with that share of the mixture.
    """
    walks = [(w * (1.0 - exchange_weight), ColorTransformWalk(
        g * scale, 0.01 * scale, 1e-4 * scale, name=f"color-transform-{g:g}"))
        for g, w in zip((0.01, 0.001, 0.0005), _SCALE_WEIGHTS)]
    return mixture(*walks, (exchange_weight, GainLightExchange(0.02 * scale,
                                                               name="gain-light-0.02")),
                   name="color-transform")


def light_proposal(solver_data: LightData | None = None, *, solver_sigma: float = 0.005,
                   solver_ridge: float = 1e-4, scale: float = 1.0) -> Mixture:
    """Build the SH light mixture, with the least-squares solver when data are given.

    Parameters
    ----------
    solver_data : callable ``(params) -> (normals, albedo, target)``, optional
        See :class:`~proposals.light_solver.SHLightSolver`. Without it the five
        reference proposals share the weight equally (as in AlbedoMM).
    solver_sigma, solver_ridge : float
        Spread of the solver's independence draw and its regularisation.
    scale : float
        Multiplier of the five random walks' step sizes.
    """
    k = scale
    five = (SHSpatial(0.05 * k, name="sh-spatial-0.05"), SHBandMixer(0.1 * k, name="sh-bands-0.1"),
            SHIntensity(0.05 * k, name="sh-intensity-0.05"),
            SHPerturbation(0.001 * k, fix_energy=True, name="sh-perturb-fixed-0.001"),
            SHColorShift(0.01 * k, name="sh-colour-0.01"))
    parts = [(5.0 / 6.0 / 5.0, p) for p in five]
    if solver_data is not None:
        parts.append((1.0 / 6.0, SHLightSolver(solver_data, sigma=solver_sigma,
                                               ridge=solver_ridge)))
    return mixture(*parts, name="light")


def specular_exponent_proposal(scale: float = 1.0) -> Mixture:
    """Log-normal scalings of the specular exponent (log sigma 0.1 and 0.02 x ``scale``)."""
    return mixture(*((0.5, SpecularExponentScaling(s * scale, name=f"specular-exponent-{s:g}"))
                     for s in (0.1, 0.02)), name="specular-exponent")


def default_image_proposal(landmark_point: LandmarkPoint | None, *,
                           solver_data: LightData | None = None, specular_weight: float = 0.1,
                           block_size: int | None = 10, solver_sigma: float = 0.005,
                           solver_ridge: float = 1e-4, albedo_data: AlbedoData | None = None,
                           albedo_weight: float = 0.25, pixel_sigma: float = 0.043,
                           expression_weight: float = 0.25,
                           scales: Scales | None = None,
                           light_conditional: LightConditional | None = None,
                           light_conditional_weight: float = 0.5,
                           extra_moves: Sequence[tuple[float, Proposal]] = ()) -> Mixture:
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
    scales : Scales, optional
        Step-size multipliers per family (:data:`FAMILIES`; set by the warm-up).
    light_conditional : LightConditional, optional
        The SH light's exact conditional draw (top-level weight
        ``light_conditional_weight``); when given, the least-squares solver
        proposal is left out (its draw is a poor match of the conditional).
    extra_moves : sequence of (weight, proposal)
        Further top-level moves (e.g. the gradient moves of :mod:`proposals.gradient`).
    """
    k = dict(scales or {})
    extra = []
    if albedo_data is not None and albedo_weight > 0:
        extra.append((albedo_weight, mixture(
            (0.5, AlbedoConditional(albedo_data, sigma=pixel_sigma)),
            (0.25, LightAlbedoExchange(albedo_data, log_sigma=0.1, sigma=pixel_sigma)),
            (0.25, LightAlbedoExchange(albedo_data, log_sigma=0.03, sigma=pixel_sigma)),
            name="albedo-conditional")))
    return mixture(
        (1.0, pose_proposal(landmark_point, scales=k)),
        (1.0, color_transform_proposal(k.get("color-transform", 1.0), exchange_weight=0.3)),
        (3.0, momo_proposal(block_size=block_size, expression_weight=expression_weight,
                            scales=k)),
        (2.0, light_proposal(None if light_conditional is not None else solver_data,
                             solver_sigma=solver_sigma, solver_ridge=solver_ridge,
                             scale=k.get("light", 1.0))),
        *([(light_conditional_weight, light_conditional)] if light_conditional is not None
          else []),
        *extra_moves,
        (specular_weight, specular_exponent_proposal(k.get("specular-exponent", 1.0))),
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


def family_of(proposal: Mixture) -> dict[str, str]:
    """Map each leaf proposal's name to its family (:data:`FAMILIES`, or the top-level name).

    The family of a leaf is the nearest enclosing mixture named in
    :data:`FAMILIES`; leaves outside every such mixture (the albedo conditional,
    the SH solver) get the name of their top-level mixture.
    """
    out: dict[str, str] = {}

    def walk(p, family: str | None, top: str | None) -> None:
        if isinstance(p, Mixture):
            fam = p.name if p.name in FAMILIES else family
            for c in p.components:
                walk(c, fam, top if top is not None else None)
            return
        out[p.name] = family or top or p.name
        inner = getattr(p, "inner", None)  # a wrapper (ImageCentered): its moves carry inner names
        if inner is not None:
            walk(inner, family, top)

    for c in proposal.components if isinstance(proposal, Mixture) else (proposal,):
        walk(c, c.name if getattr(c, "name", "") in FAMILIES else None,
             getattr(c, "name", None))
    return out
