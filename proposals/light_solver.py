"""The SH least-squares light proposal: a ridge-regularised solve plus a Gaussian independence draw.

Given surface points seen in the target image (world-frame unit normals, the
model's diffuse albedo and the target colour there, linearised and with the
colour transform inverted), the diffuse SH-Lambert model
``I_pc = rho_pc sum_i A_i Y_i(n_p) L_ic`` is linear in the light L (9, 3); the
proposal solves for L and draws around the solution. Only the diffuse part is
modelled (no specular term).

This module imports only :mod:`albedo_model` (errors, params, sh) and
:mod:`proposals.base`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block, SHLight
from albedo_model.sh import LAMBERT_FACTORS, MAX_SH_COEFFICIENTS, sh_basis
from proposals.base import Move, ProposalState, check_scale, no_move

__all__ = ["solve_sh_light", "SHLightSolver", "LightData"]

#: ``data(state) -> (normals (P, 3), albedo (P, 3), target (P, 3))`` of the accepted state;
#: see :class:`SHLightSolver`.
LightData = Callable[[ProposalState], tuple[np.ndarray, np.ndarray, np.ndarray]]


def solve_sh_light(normals: np.ndarray, albedo: np.ndarray, target: np.ndarray, *,
                   ridge: float = 1e-4) -> np.ndarray:
    """Ridge least-squares SH light of a diffuse (Lambert) surface.

    Minimises, per colour channel c independently,
    ``(1/P) sum_p (rho_pc sum_i A_i Y_i(n_p) L_ic - I_pc)^2 + ridge sum_i L_ic^2``.

    Parameters
    ----------
    normals : (P, 3) float array, world frame
        Surface normals (renormalised here; zero normals are dropped).
    albedo : (P, 3) float array
        Linear RGB diffuse albedo at the points.
    target : (P, 3) float array
        Observed linear RGB at the points (colour transform already inverted).
    ridge : float
        Regularisation weight (>= 0), per point-averaged squared residual; it
        keeps the system full rank with few points (e.g. 3).

    Returns
    -------
    (9, 3) float64
        Radiance environment map L in scalismo's order. Rows with non-finite
        values or zero normals are ignored; with no usable point (and
        ``ridge > 0``) the result is zero.

    Raises
    ------
    InputError
        Mismatched shapes, negative ridge, or a numerically singular system
        (too few or degenerate points with ``ridge`` zero or negligible).
    """
    n = np.asarray(normals, np.float64)
    rho = np.asarray(albedo, np.float64)
    img = np.asarray(target, np.float64)
    if n.ndim != 2 or n.shape[1] != 3 or rho.shape != n.shape or img.shape != n.shape:
        raise InputError(
            f"normals, albedo and target must all be (P, 3); got {n.shape}, {rho.shape}, "
            f"{img.shape}"
        )
    ridge = check_scale(ridge, "ridge", allow_zero=True)
    norm = np.linalg.norm(n, axis=1)
    keep = (norm > 0) & np.isfinite(norm + rho.sum(1) + img.sum(1))
    if not keep.all():
        n, rho, img, norm = n[keep], rho[keep], img[keep], norm[keep]
    n = n / norm[:, None]
    p = n.shape[0]
    k = MAX_SH_COEFFICIENTS
    if p == 0:
        if ridge > 0:
            return np.zeros((k, 3))
        raise InputError("SH light solve: no usable point and no regularisation")
    basis = sh_basis(n, k) * LAMBERT_FACTORS  # (P, 9)
    # per channel c: X_c = diag(rho_c) B; normal equations (X_c^T X_c + ridge P I) L_c = X_c^T I_c
    weighted = rho.T[:, :, None] * basis[None]  # (3, P, 9)
    gram = weighted.transpose(0, 2, 1) @ weighted  # (3, 9, 9)
    rhs = weighted.transpose(0, 2, 1) @ img.T[:, :, None]  # (3, 9, 1)
    gram += ridge * p * np.eye(k)
    eig = np.linalg.eigvalsh(gram)
    if np.any(eig[:, 0] <= 1e-12 * np.maximum(eig[:, -1], np.finfo(float).tiny)):
        raise InputError("SH light solve: singular system (too few or degenerate points); "
                         "use ridge > 0")
    L = np.linalg.solve(gram, rhs)[..., 0].T
    return L


@dataclass(frozen=True)
class SHLightSolver:
    """Independence proposal ``L' ~ N(mu, sigma^2 I)`` around the least-squares light mu.

    Parameters
    ----------
    data : callable ``(ProposalState) -> (normals, albedo, target)``
        Per-point arrays (P, 3) each, as in :func:`solve_sh_light`, computed
        from the accepted state the move starts from. They must not depend on the light
        (they may depend on geometry, pose, camera, albedo and colour transform).
    sigma : float
        Standard deviation of the draw around mu, per coefficient.
    ridge : float
        Regularisation of the solve.
    name : str, optional (default ``"sh-solver"``)

    Notes
    -----
    ``mu`` is a function of the non-light coordinates only, which the move
    leaves unchanged, so the same mu serves forward and backward and
    ``q(L'|L) = N(L'; mu, sigma^2)``: the exact ratio is
    ``log N(L; mu, sigma^2) - log N(L'; mu, sigma^2)
    = (||L' - mu||^2 - ||L - mu||^2) / (2 sigma^2)``.
    The reference uses the solution itself with a ratio of 0, which is not a
    valid MH proposal (a point mass). The current light must have 9
    coefficients (the solver's size). With no data point the move is the
    identity (the condition does not depend on the light).
    """

    data: LightData
    sigma: float = 0.01
    ridge: float = 1e-4
    name: str = "sh-solver"
    touches: ClassVar[Block] = Block.LIGHT

    def __post_init__(self) -> None:
        """Validate ``sigma`` and ``ridge``."""
        check_scale(self.sigma, "SH solver sigma")
        check_scale(self.ridge, "ridge", allow_zero=True)

    def mean(self, state: ProposalState) -> np.ndarray | None:
        """Return the least-squares light mu (9, 3) at ``state``, or None without data points."""
        normals, albedo, target = self.data(state)
        if np.asarray(normals).shape[0] == 0:
            return None
        return solve_sh_light(normals, albedo, target, ridge=self.ridge)

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        L = np.asarray(params.environment_map.coefficients, np.float64)
        if L.shape != (MAX_SH_COEFFICIENTS, 3):
            raise InputError(f"SH solver proposal needs a (9, 3) light, got {L.shape}")
        mu = self.mean(state)
        eps = rng.normal(0.0, self.sigma, L.shape)
        if mu is None:
            return no_move(params, self.name)
        L_new = mu + eps
        ratio = (float(np.sum(eps**2)) - float(np.sum((L - mu) ** 2))) / (2.0 * self.sigma**2)
        return Move(params._replace(environment_map=SHLight(L_new)), ratio, Block.LIGHT,
                    self.name, joint=True)
