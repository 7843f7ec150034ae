"""Proposals on the model coefficients: Gaussian random walks and caricature scaling.

The coefficient vectors live in ``params.momo``: ``shape`` (Block.SHAPE),
``expression`` (Block.EXPRESSION) and ``albedo`` (Block.ALBEDO, the coefficient
vector shared by diffuse and specular albedo). They are standard-normal PCA
coefficients, so the scales are in prior standard deviations.

This module imports only :mod:`albedo_model.errors`, :mod:`albedo_model.params` and
:mod:`proposals.base`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block, RenderParameter
from proposals.base import Move, ProposalState, check_scale, no_move

__all__ = ["COEFFICIENT_FIELDS", "CoefficientWalk", "Caricature"]

#: ``MoMoCoefficients`` field of each coefficient block.
COEFFICIENT_FIELDS = {Block.SHAPE: "shape", Block.EXPRESSION: "expression", Block.ALBEDO: "albedo"}
_LABELS = {Block.SHAPE: "shape", Block.EXPRESSION: "expression", Block.ALBEDO: "albedo"}


def _check_block(block: Block) -> str:
    if block not in COEFFICIENT_FIELDS:
        raise InputError(f"coefficient block must be SHAPE, EXPRESSION or ALBEDO, got {block!r}")
    return COEFFICIENT_FIELDS[block]


def _with(params: RenderParameter, fld: str, values: np.ndarray) -> RenderParameter:
    return params._replace(momo=params.momo._replace(**{fld: values}))


@dataclass(frozen=True)
class CoefficientWalk:
    """Gaussian random walk on all coefficients of a block or on a contiguous part.

    Parameters
    ----------
    block : Block
        ``Block.SHAPE``, ``Block.EXPRESSION`` or ``Block.ALBEDO``.
    sigma : float
        Step standard deviation per coefficient (prior units).
    index : slice, optional
        Move only ``coefficients[index]`` (a fixed contiguous part).
    block_size : int, optional
        Move one chunk ``[j b, (j + 1) b)`` (the last one may be shorter), with
        ``j`` drawn uniformly among the ``ceil(n / b)`` chunks. The renderer's
        cost of an albedo or shape update is proportional to the number of
        moved coefficients, so chunks of ~10 are cheap units.
        Without ``index`` and ``block_size`` every coefficient moves (the reference).
    name : str, optional (default ``"<block>-<sigma>"``, e.g. ``"shape-0.2"``)

    Notes
    -----
    ``x'_J = x_J + N(0, sigma^2 I)`` on the chosen index set J, the rest kept.
    The chunk is chosen independently of the state, and for a given chunk the
    step is symmetric, so ``q(x'|x) = q(x|x')``: ratio 0. An empty vector (or
    empty slice) gives the identity move.
    """

    block: Block
    sigma: float
    index: slice | None = None
    block_size: int | None = None
    name: str = ""
    touches: Block = field(init=False)

    def __post_init__(self) -> None:
        """Validate the block and scales, set ``touches`` and a default name."""
        _check_block(self.block)
        check_scale(self.sigma, "coefficient walk sigma")
        if self.index is not None and self.block_size is not None:
            raise InputError("give either index or block_size, not both")
        if self.block_size is not None and int(self.block_size) < 1:
            raise InputError(f"block_size must be >= 1, got {self.block_size!r}")
        object.__setattr__(self, "touches", self.block)
        if not self.name:
            object.__setattr__(self, "name", f"{_LABELS[self.block]}-{self.sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        fld = COEFFICIENT_FIELDS[self.block]
        x = np.asarray(getattr(params.momo, fld), np.float64)
        n = x.shape[0]
        if self.index is not None:
            start, stop, step = self.index.indices(n)
            if step != 1:
                raise InputError(f"coefficient index must be contiguous, got {self.index!r}")
        elif self.block_size is not None and n > 0:
            b = int(self.block_size)
            start = b * int(rng.integers(0, -(-n // b)))
            stop = min(start + b, n)
        else:
            start, stop = 0, n
        if stop <= start:
            return no_move(params, self.name)
        x_new = x.copy()
        x_new[start:stop] += rng.normal(0.0, self.sigma, stop - start)
        return Move(_with(params, fld, x_new), 0.0, self.block, self.name)


@dataclass(frozen=True)
class Caricature:
    """Scale a whole coefficient vector: ``x' = s x`` with ``s = exp(N(0, sigma))``.

    Parameters
    ----------
    block : Block
        ``Block.SHAPE``, ``Block.EXPRESSION`` or ``Block.ALBEDO``.
    sigma : float
        Standard deviation of ``log s``.
    name : str, optional (default ``"<block>-caricature-<sigma>"``)

    Notes
    -----
    In polar coordinates ``x = r u`` (r > 0, u on the unit sphere of R^k),
    Lebesgue measure is ``r^(k-1) dr du``; the move keeps u and draws r'
    log-normally about r, ``q(r'|r) = phi(log r' - log r) / r'``. A target
    ``p(x)`` reads ``p(r u) r^(k-1)`` in (r, u), so the MH ratio is
    ``p(x')/p(x) (r'/r)^(k-1) (r'/r)``: ``log_q_ratio = k log s`` for k
    coefficients (the reference's version returns -inf, a bug). A zero (or
    empty) vector gives the identity move.
    """

    block: Block
    sigma: float
    name: str = ""
    touches: Block = field(init=False)

    def __post_init__(self) -> None:
        """Validate the block and scale, set ``touches`` and a default name."""
        _check_block(self.block)
        check_scale(self.sigma, "caricature sigma")
        object.__setattr__(self, "touches", self.block)
        if not self.name:
            object.__setattr__(self, "name", f"{_LABELS[self.block]}-caricature-{self.sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        fld = COEFFICIENT_FIELDS[self.block]
        x = np.asarray(getattr(params.momo, fld), np.float64)
        log_s = rng.normal(0.0, self.sigma)
        if not np.any(x):
            return no_move(params, self.name)
        return Move(_with(params, fld, x * np.exp(log_s)), float(x.shape[0] * log_s),
                    self.block, self.name)
