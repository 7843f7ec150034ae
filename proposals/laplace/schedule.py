"""The Gaussian sampler's image-stage schedule: Crank-Nicolson, Gaussian blocks, a walk, exact conditionals.

:func:`gaussian_image_proposal` mixes the moves of :mod:`proposals.laplace.moves`
built on a fit's Laplace approximation, the geometry's random walk shaped by it
(:mod:`proposals.laplace.random_walk`: the move that keeps a chain moving where
the posterior is wider than the approximation) and the albedo's and the SH
light's exact conditionals. Each Gaussian family has a step ``sqrt(1 - rho^2)``
(:data:`GAUSSIAN_STEPS`), the walk a step in conditional sds, that the warm-up
multiplies towards an acceptance rate (:data:`GAUSSIAN_TARGETS`); :func:`rho_of`
turns a multiplier into ``rho``.

This module imports :mod:`proposals` (albedo_solver, base, light_conditional,
schedule) and :mod:`proposals.laplace` (coordinates, moves, random_walk).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

import numpy as np

from proposals.albedo_offset import AlbedoOffsetConditional, ContrastAlbedoExchange
from proposals.albedo_solver import AlbedoConditional, AlbedoData
from proposals.base import Mixture, Proposal, mixture
from proposals.laplace.coordinates import SamplingCoordinates
from proposals.laplace.moves import (
    CoordinateGradient, CrankNicolson, GaussianApproximation, GaussianBlockConditional, GaussianHMC,
)
from proposals.laplace.random_walk import GaussianRandomWalk
from proposals.light_conditional import ContrastLightExchange, LightConditional
from proposals.schedule import Scales

__all__ = ["BLOCK_SHARES", "CONTRAST_STEP", "GAUSSIAN_BLOCKS", "GAUSSIAN_FAMILIES", "GAUSSIAN_STEPS",
           "GAUSSIAN_TARGETS", "GEOMETRY_COORDINATES", "HMC_STEP", "WALK_SCALE", "WIDE_FACTOR",
           "gaussian_image_proposal", "rho_of", "walk_scale"]

#: A joint fit's per-image coordinate-name prefix (:mod:`proposals.laplace.joint_coordinates`).
_IMAGE_PREFIX = re.compile(r"^image\d+\.")

#: The Gaussian moves' families (warm-up adapts one step multiplier each).
GAUSSIAN_FAMILIES = ("pcn", "gaussian-geometry", "gaussian-albedo", "gaussian-shading",
                     "geometry-walk", "geometry-wide", "hmc", "contrast-exchange", "contrast-light")

#: Initial Crank-Nicolson step ``sqrt(1 - rho^2)`` of the Gaussian moves' families (the
#: warm-up multiplies it by the family's multiplier, at most to 1: an independent draw).
GAUSSIAN_STEPS = {"pcn": 0.85, "gaussian-geometry": 0.8, "gaussian-albedo": 1.0,
                  "gaussian-shading": 0.8, "geometry-wide": 0.5}

#: Acceptance rates the warm-up tunes the Gaussian families' steps to (measured on the demo
#: face: the Crank-Nicolson move's effective samples per step peak near 0.2 acceptance).
GAUSSIAN_TARGETS = {"pcn": 0.2, "gaussian-geometry": 0.3, "gaussian-albedo": 0.3,
                    "gaussian-shading": 0.3, "geometry-walk": 0.25, "geometry-wide": 0.25,
                    "hmc": 0.65, "contrast-exchange": 0.4, "contrast-light": 0.4}

#: Initial step of the geometry's random walk, in conditional sds per coordinate, times
#: ``1 / sqrt(k)`` for a block of ``k`` coordinates (2.4 / sqrt(k): the optimal walk's
#: step where the posterior matches the approximation; Roberts, Gelman & Gilks 1997).
WALK_SCALE = 2.4

#: Initial contrast step of :class:`~proposals.albedo_offset.ContrastAlbedoExchange`, in
#: the contrast's marginal sds under the approximation (the warm-up multiplies it): the
#: contrast's conditional given the rest is ~10x narrower, which the exchange need not
#: respect, as it redraws the albedo and offsets under the new contrast.
CONTRAST_STEP = 2.0

#: Initial leapfrog step of the whitened HMC move (whitened units; the warm-up multiplies it).
HMC_STEP = 0.5

#: Shares of the block moves' top-level weight. The albedo and shading blocks cost a
#: re-shading (1-2 ms) where a geometry move re-casts the rays (~14 ms at 250^2).
BLOCK_SHARES = {"gaussian-geometry": 0.25, "geometry-wide": 0.15, "geometry-walk": 0.2,
                "gaussian-albedo": 0.2, "gaussian-shading": 0.2}

#: Sd factor of the approximation the "geometry-wide" block draws use: reversible with
#: respect to a Gaussian twice as wide in the geometry, their acceptance ``w(u') / w(u)``
#: (``w`` the posterior over that Gaussian) stays moderate where the posterior's tails
#: outreach the Laplace approximation's, so a chain out there is drawn back in large steps.
WIDE_FACTOR = 2.0

#: The geometry's coordinates (by name prefix): the distance's is ``log_distance`` or
#: ``inverse_distance``, the focal length's ``log_focal_length`` or ``log_image_size``
#: (:mod:`proposals.laplace.coordinates`).
GEOMETRY_COORDINATES = ("shape", "expression", "angles", "translation", "log_distance",
                        "inverse_distance", "log_focal_length", "log_image_size",
                        "principal_point")

#: The coordinates of the Gaussian moves' blocks (by name prefix, :mod:`proposals.laplace.coordinates`).
GAUSSIAN_BLOCKS = {
    "gaussian-geometry": GEOMETRY_COORDINATES,
    "geometry-walk": GEOMETRY_COORDINATES,
    "geometry-wide": GEOMETRY_COORDINATES,
    "gaussian-albedo": ("albedo",),
    "gaussian-shading": ("light", "gain", "contrast", "offset", "log_specular_exponent",
                         "log_light_intensity"),
}


def rho_of(family: str, scales: Scales | None) -> float:
    """Return the Crank-Nicolson ``rho`` of a Gaussian family at its step multiplier."""
    step = min(1.0, GAUSSIAN_STEPS[family] * float((scales or {}).get(family, 1.0)))
    return math.sqrt(max(0.0, 1.0 - step * step))


def walk_scale(k: int, scales: Scales | None) -> float:
    """Return the geometry walk's step (conditional sds) for a ``k``-coordinate block at its multiplier."""
    return WALK_SCALE / math.sqrt(max(1, k)) * float((scales or {}).get("geometry-walk", 1.0))


def gaussian_image_proposal(coords: SamplingCoordinates, approx: GaussianApproximation, *,
                            scales: Scales | None = None,
                            albedo_data: AlbedoData | None = None, pixel_sigma: float = 0.043,
                            light_conditional: LightConditional | None = None,
                            pcn_weight: float = 0.3, block_weight: float = 0.4,
                            albedo_weight: float = 0.2,
                            light_conditional_weight: float = 0.1,
                            gradient: CoordinateGradient | None = None, hmc_weight: float = 0.0,
                            hmc_leapfrog: int = 4, hmc_random_steps: bool = False,
                            contrast_light: bool = False, offset_sd: float | None = None,
                            extra_moves: Sequence[tuple[float, Proposal]] = ()) -> Mixture:
    """Build the image-stage proposal of the Gaussian sampler (the default).

    Parameters
    ----------
    coords : SamplingCoordinates
    approx : GaussianApproximation
        The posterior's Laplace approximation in ``coords`` (:mod:`mcmcfit.fitting.mode`).
    scales : Scales, optional
        Step multipliers of the families :data:`GAUSSIAN_FAMILIES` (:func:`rho_of`;
        set by the warm-up).
    albedo_data : callable, optional
        Data of the albedo's exact conditional (:class:`~proposals.albedo_solver.AlbedoConditional`).
    pixel_sigma : float
        The likelihood's effective pixel sd (for the albedo conditional).
    light_conditional : LightConditional, optional
        The SH light's exact conditional.
    pcn_weight, block_weight, albedo_weight, light_conditional_weight : float
        Top-level weights: Crank-Nicolson moves of every coordinate; block
        moves from the approximation's conditionals (shared as :data:`BLOCK_SHARES`);
        the albedo's and the light's exact conditionals (each rebuilds its linear
        system over the region after a geometry move: 15-30 ms at 250^2).
    gradient : callable, optional
        ``gradient(params) -> (log density, gradient in u)`` of the posterior
        (:func:`mcmcfit.targets.curvature.coordinate_gradient`); with ``hmc_weight > 0``
        the mixture gets a whitened HMC move of every coordinate
        (:class:`~proposals.laplace.moves.GaussianHMC`, family ``"hmc"``).
    hmc_weight : float
        Top-level weight of the HMC move.
    hmc_leapfrog : int
        Leapfrog steps per HMC move (each a ray cast and a gradient).
    hmc_random_steps : bool
        Draw each HMC move's number of steps from 1 to ``2 hmc_leapfrog - 1``.
    contrast_light : bool
        With ``light_conditional``: also step the colour contrast with the light
        redrawn under it (:class:`~proposals.light_conditional.ContrastLightExchange`,
        family ``"contrast-light"``, the light conditional's weight).
    offset_sd : float, optional
        Prior sd of the colour offsets: the albedo's exact conditional draws
        them with the albedo coefficients
        (:class:`~proposals.albedo_offset.AlbedoOffsetConditional`), and a move
        of the colour contrast redraws both under the new contrast, with the
        albedo conditional's weight
        (:class:`~proposals.albedo_offset.ContrastAlbedoExchange`, family
        ``"contrast-exchange"``); None: the albedo alone
        (:class:`~proposals.albedo_solver.AlbedoConditional`).
    extra_moves : sequence of (weight, proposal)
        Further top-level moves (a joint fit's conditionals over several images).

    Notes
    -----
    The blocks are chosen by coordinate name with any ``image<i>.`` prefix
    removed, so for a joint fit's coordinates
    (:class:`~proposals.laplace.joint_coordinates.JointCoordinates`) a block is
    the shared identity's part and every image's part of it together.

    Returns
    -------
    Mixture
    """
    k = dict(scales or {})
    names = np.array([_IMAGE_PREFIX.sub("", n) for n in coords.names])
    parts = [(pcn_weight, mixture((1.0, CrankNicolson(coords, approx, rho_of("pcn", k),
                                                      name="pcn")), name="pcn"))]
    for family, share in BLOCK_SHARES.items():
        mask = np.array([n.startswith(GAUSSIAN_BLOCKS[family]) for n in names])
        if mask.any() and block_weight > 0:
            if family == "geometry-walk":
                move = GaussianRandomWalk(coords, approx, mask,
                                          walk_scale(int(mask.sum()), k), name=family)
            else:
                base = approx.widened(mask, WIDE_FACTOR) if family == "geometry-wide" else approx
                move = GaussianBlockConditional(coords, base, mask, name=family,
                                                rho=rho_of(family, k))
            parts.append((share * block_weight, mixture((1.0, move), name=family)))
    if albedo_data is not None and albedo_weight > 0:
        parts.append((albedo_weight, AlbedoConditional(albedo_data, sigma=pixel_sigma)
                      if offset_sd is None else
                      AlbedoOffsetConditional(albedo_data, sigma=pixel_sigma, offset_sd=offset_sd)))
        at = np.flatnonzero(names == "contrast")
        if offset_sd is not None and at.size:
            chol = np.asarray(approx.chol_cov)[at[0]]
            step = CONTRAST_STEP * float(np.sqrt(chol @ chol)) * float(
                k.get("contrast-exchange", 1.0))
            parts.append((albedo_weight, mixture((1.0, ContrastAlbedoExchange(
                albedo_data, step=step, sigma=pixel_sigma, offset_sd=offset_sd)),
                name="contrast-exchange")))
    if light_conditional is not None and light_conditional_weight > 0:
        parts.append((light_conditional_weight, light_conditional))
        at = np.flatnonzero(names == "contrast")
        if contrast_light and at.size:
            chol = np.asarray(approx.chol_cov)[at[0]]
            step = CONTRAST_STEP * float(np.sqrt(chol @ chol)) * float(k.get("contrast-light", 1.0))
            lc = light_conditional
            parts.append((light_conditional_weight, mixture((1.0, ContrastLightExchange(
                lc.data, lc.prior_mean, lc.prior_sd, sigma=lc.sigma, step=step)),
                name="contrast-light")))
    parts += [(w, move) for w, move in extra_moves if w > 0]
    if gradient is not None and hmc_weight > 0:
        step = HMC_STEP * float(k.get("hmc", 1.0))
        parts.append((hmc_weight, mixture((1.0, GaussianHMC(
            coords, approx, gradient, step, hmc_leapfrog, name="hmc",
            random_steps=hmc_random_steps)),
                                          name="hmc")))
    return mixture(*parts, name="image")
