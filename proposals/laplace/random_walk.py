"""A random walk shaped by the Gaussian approximation: the move that cannot get stuck on its tails.

The moves of :mod:`proposals.laplace.moves` are reversible with respect to the
approximation ``N(m, S)``, so their Metropolis-Hastings acceptance is
``min(1, w(u') / w(u))`` with ``w = pi / N`` the target over the
approximation. Where the posterior is wider than its Laplace approximation
(the geometry's curved ridges: shape against distance and translation) a
chain that walks out along the ridge reaches states of very large ``w``, and
every large Crank-Nicolson or block draw, which lands back where ``w`` is
typical, is refused: measured on the demo face, a chain held its geometry for
2,700 steps with all ~1,600 geometry moves rejected while the log posterior
stayed typical.

:class:`GaussianRandomWalk` is the remedy: a symmetric random walk of one
block, ``u_b' = u_b + s L_b z`` with ``L_b L_b^T = (P_bb)^-1`` the block's
conditional covariance under the approximation. The approximation only
*shapes* the step; its density is not in the ratio, which is the posterior's
alone (plus the coordinates' ``log |dx/du|``), so the walk moves wherever the
posterior is locally smooth, however far into the approximation's tails.

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.params`,
:mod:`proposals.base` and :mod:`proposals.laplace` (coordinates, moves).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block
from proposals.base import Move, ProposalState
from proposals.laplace.coordinates import SamplingCoordinates
from proposals.laplace.moves import GaussianApproximation

__all__ = ["GaussianRandomWalk"]


@dataclass(frozen=True, eq=False)
class GaussianRandomWalk:
    """Symmetric random walk of the coordinates of ``mask``, shaped by the block's conditional covariance.

    Parameters
    ----------
    coords : SamplingCoordinates
    approx : GaussianApproximation
    mask : (d,) bool
        The coordinates the move changes (a non-empty subset).
    scale : float > 0
        Step ``s`` in units of the conditional sd (about ``2.4 / sqrt(k)`` for a
        ``k``-coordinate block whose posterior matches the approximation).
    name : str

    Notes
    -----
    The step's law does not depend on the state, so the proposal is symmetric
    in ``u`` and the ratio is ``log |dx/du|(u') - log |dx/du|(u)``.
    """

    coords: SamplingCoordinates
    approx: GaussianApproximation
    mask: np.ndarray
    scale: float = 0.3
    name: str = "gaussian-walk"
    touches: Block = field(init=False)
    _idx: np.ndarray = field(init=False, repr=False)
    _chol_pbb: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Validate, factorise the block's conditional precision and set ``touches``."""
        if self.coords.size != self.approx.size:
            raise InputError(f"Gaussian approximation has {self.approx.size} coordinates, "
                             f"the sampling coordinates {self.coords.size}")
        if not (math.isfinite(self.scale) and self.scale > 0.0):
            raise InputError(f"random-walk scale must be positive, got {self.scale!r}")
        mask = np.asarray(self.mask, bool).reshape(-1)
        if mask.shape[0] != self.approx.size or not mask.any():
            raise InputError("random-walk mask must select some of the coordinates")
        idx = np.flatnonzero(mask)
        chol = np.linalg.cholesky(self.approx.precision[np.ix_(idx, idx)])
        object.__setattr__(self, "_idx", idx)
        object.__setattr__(self, "_chol_pbb", chol)
        object.__setattr__(self, "touches", self.coords.blocks_of(mask))

    def with_scale(self, scale: float) -> GaussianRandomWalk:
        """Return this move with another step ``scale`` (same block and name)."""
        return GaussianRandomWalk(self.coords, self.approx, self.mask, scale, self.name)

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        c = self.coords
        u = c.u_of(state.params)
        step = np.linalg.solve(self._chol_pbb.T, rng.normal(size=self._idx.size))
        u_new = u.copy()
        u_new[self._idx] += self.scale * step
        ratio = c.log_jacobian(u_new) - c.log_jacobian(u)
        return Move(c.params_of(u_new, state.params), ratio, self.touches, self.name,
                    joint=True)
