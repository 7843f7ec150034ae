"""Metropolis-Hastings proposals over the fit parameters.

Every proposal is a pure callable ``(rng, state) -> Move`` that declares the
parameter blocks it may change (``touches``) and returns the exact log
transition ratio ``log q(x | x') - log q(x' | x)``. Modules: ``base`` (interface,
mixtures), ``pose``, ``coefficients``, ``color_transform`` (walks and the
gain-light exchange), ``light``, ``light_solver`` (the SH least-squares light),
``light_conditional`` (the SH light's exact conditional), ``albedo_solver`` (the
albedo conditional), ``gradient`` (preconditioned MALA and HMC on the geometry),
``schedule`` (the default mixtures), ``joint`` (several images of one face: the
joint state, single-image moves lifted to it, the shared albedo conditional).

The package imports only :mod:`albedo_model` (camera, errors, params, sh). This file
imports every module of the package but ``albedo_solver``, ``gradient``, ``joint`` and
``light_conditional``.
"""

from proposals.base import Mixture, Move, Proposal, ProposalState, leaves, mixture, no_move
from proposals.coefficients import Caricature, CoefficientWalk
from proposals.color_transform import ColorTransformWalk, GainLightExchange
from proposals.light import (
    SHBandMixer,
    SHColorShift,
    SHIntensity,
    SHPerturbation,
    SHSpatial,
    SpecularExponentScaling,
)
from proposals.light_solver import SHLightSolver, solve_sh_light
from proposals.pose import Distance, FocalScaling, ImageCentered, Rotation, Translation
from proposals.schedule import (
    CENTERING_LANDMARKS,
    color_transform_proposal,
    default_image_proposal,
    landmark_stage_proposal,
    light_proposal,
    momo_proposal,
    pose_proposal,
    specular_exponent_proposal,
)

__all__ = [
    "Move", "Proposal", "ProposalState", "Mixture", "mixture", "leaves", "no_move",
    "Rotation", "Translation", "Distance", "FocalScaling", "ImageCentered",
    "CoefficientWalk", "Caricature", "ColorTransformWalk", "GainLightExchange",
    "SHIntensity", "SHBandMixer", "SHPerturbation", "SHColorShift", "SHSpatial",
    "SpecularExponentScaling", "SHLightSolver", "solve_sh_light",
    "CENTERING_LANDMARKS", "pose_proposal", "momo_proposal", "color_transform_proposal",
    "light_proposal", "specular_exponent_proposal", "default_image_proposal",
    "landmark_stage_proposal",
]
