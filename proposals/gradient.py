"""Gradient-informed moves: preconditioned MALA on a flat vector of continuous blocks.

The flat vector (:func:`block_vector`, :func:`with_block_vector`) holds the
continuous parameters of the chosen blocks, always in this order:

===========  ==========================================  ===================
block        entries                                     units
===========  ==========================================  ===================
SHAPE        ``momo.shape`` (all of them)                prior sds
EXPRESSION   ``momo.expression``                         prior sds
POSE         yaw, pitch, roll, t_x, t_y, t_z             rad, rad, rad, mm
CAMERA       ``camera.focal_length``                     sensor units
===========  ==========================================  ===================

Pose scaling, the principal point and the sensor are not in it (the principal
point moves with the image-centred random walks of :mod:`proposals.pose`).
:class:`MALA` (and :class:`HMC`, several leapfrog steps) moves the whole vector
with the gradient of the log posterior, computed by an injected callable
(``grad(params) -> (log_density, gradient)``, e.g.
:func:`mcmcfit.targets.gradient.posterior_gradient`), so that this package does
not depend on how the posterior is evaluated.

This module imports only :mod:`albedo_model.errors`, :mod:`albedo_model.params` and
:mod:`proposals.base`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block, RenderParameter
from proposals.base import Move, ProposalState, check_scale

__all__ = [
    "GRADIENT_BLOCKS",
    "HMC",
    "MALA",
    "POSE_ENTRIES",
    "GradFn",
    "block_vector",
    "mala_log_q_ratio",
    "leapfrog",
    "mala_mean",
    "vector_layout",
    "with_block_vector",
]

#: The blocks a gradient move can take (continuous, and differentiable through the render).
GRADIENT_BLOCKS = Block.SHAPE | Block.EXPRESSION | Block.POSE | Block.CAMERA
#: Names of the POSE entries of the flat vector, in order.
POSE_ENTRIES = ("yaw", "pitch", "roll", "t_x", "t_y", "t_z")

#: ``grad(params) -> (log_density, gradient)``: the gradient, (d,) float64 in the layout of
#: :func:`vector_layout`, of a log density at ``params`` (a function of ``params`` only).
GradFn = Callable[[RenderParameter], tuple[float, np.ndarray]]


def _check_blocks(blocks: Block) -> Block:
    blocks = Block(blocks)
    if not blocks or blocks & ~GRADIENT_BLOCKS:
        raise InputError(f"gradient blocks must be a non-empty part of SHAPE | EXPRESSION | "
                         f"POSE | CAMERA, got {blocks!r}")
    return blocks


def vector_layout(params: RenderParameter, blocks: Block) -> tuple[tuple[Block, int], ...]:
    """Return the ``(block, length)`` runs of the flat vector of ``blocks`` at ``params``."""
    blocks = _check_blocks(blocks)
    runs = []
    if blocks & Block.SHAPE:
        runs.append((Block.SHAPE, len(params.momo.shape)))
    if blocks & Block.EXPRESSION:
        runs.append((Block.EXPRESSION, len(params.momo.expression)))
    if blocks & Block.POSE:
        runs.append((Block.POSE, len(POSE_ENTRIES)))
    if blocks & Block.CAMERA:
        runs.append((Block.CAMERA, 1))
    return tuple(runs)


def block_vector(params: RenderParameter, blocks: Block) -> np.ndarray:
    """Return the flat vector (d,) float64 of ``blocks`` at ``params`` (module table order)."""
    p = params
    parts = {Block.SHAPE: lambda: p.momo.shape, Block.EXPRESSION: lambda: p.momo.expression,
             Block.POSE: lambda: (p.pose.yaw, p.pose.pitch, p.pose.roll, *p.pose.translation),
             Block.CAMERA: lambda: (p.camera.focal_length,)}
    runs = vector_layout(params, blocks)
    if not runs:
        return np.zeros(0)
    return np.concatenate([np.asarray(parts[b](), np.float64).reshape(-1) for b, _ in runs])


def with_block_vector(params: RenderParameter, blocks: Block, x: np.ndarray) -> RenderParameter:
    """Return ``params`` with the entries of ``blocks`` replaced by the flat vector ``x``."""
    x = np.asarray(x, np.float64).reshape(-1)
    runs = vector_layout(params, blocks)
    if x.shape[0] != sum(n for _, n in runs):
        raise InputError(f"flat vector has {x.shape[0]} entries, the layout {runs} needs "
                         f"{sum(n for _, n in runs)}")
    p, start = params, 0
    for block, n in runs:
        v = x[start:start + n]
        start += n
        if block == Block.SHAPE:
            p = p._replace(momo=p.momo._replace(shape=v.copy()))
        elif block == Block.EXPRESSION:
            p = p._replace(momo=p.momo._replace(expression=v.copy()))
        elif block == Block.POSE:
            p = p._replace(pose=p.pose._replace(
                yaw=float(v[0]), pitch=float(v[1]), roll=float(v[2]),
                translation=(float(v[3]), float(v[4]), float(v[5]))))
        else:
            p = p._replace(camera=p.camera._replace(focal_length=float(v[0])))
    return p


def mala_mean(x: np.ndarray, drift: np.ndarray, step: float, diag: np.ndarray) -> np.ndarray:
    """Return the mean ``x + (eps^2 / 2) M g`` of the Langevin proposal from ``x``."""
    return x + 0.5 * step * step * diag * drift


def mala_log_q_ratio(x: np.ndarray, x_new: np.ndarray, drift: np.ndarray, drift_new: np.ndarray,
                     step: float, diag: np.ndarray) -> float:
    """Return ``log q(x | x') - log q(x' | x)`` of the Langevin proposal ``N(mean(x), eps^2 M)``.

    ``drift`` and ``drift_new`` are the gradients at ``x`` and at ``x'``; the
    Gaussian normalisers are the same both ways and cancel.
    """
    fwd = x_new - mala_mean(x, drift, step, diag)
    bwd = x - mala_mean(x_new, drift_new, step, diag)
    scale = 0.5 / (step * step)
    return float(scale * (np.sum(fwd * fwd / diag) - np.sum(bwd * bwd / diag)))


class _GradientCache:
    """The gradients of the last two points a MALA proposal evaluated, keyed by their params object.

    Holds ``(params, drift)`` pairs and returns ``drift`` only for the very same
    ``RenderParameter`` object (``is``): the sampler hands a proposal the accepted
    state's ``params``, which is either the start of the last move (rejected) or
    the object the last move proposed (accepted: :func:`mcmcfit.sampling.kernel.step`
    keeps ``move.params`` itself). Any other state (another proposal moved the
    chain: light, albedo, ... change the gradient too) misses. The pairs hold a
    reference to their objects, so an id is never reused while kept; the
    parameters are immutable (proposals never modify arrays in place).
    """

    def __init__(self) -> None:
        self._entries: list[tuple[RenderParameter, np.ndarray]] = []

    def drift(self, grad: GradFn, params: RenderParameter, size: int) -> np.ndarray:
        """Return the kept drift of ``params``, else ``grad(params)``'s (0 where not finite)."""
        kept = [d for key, d in self._entries if key is params]
        return kept[0] if kept else _as_drift(grad(params), size)

    def keep(self, *entries: tuple[RenderParameter, np.ndarray]) -> None:
        """Keep exactly these ``(params, drift)`` pairs (the current point and the proposed one)."""
        self._entries = list(entries)


def _checked_diag(diag) -> np.ndarray | None:
    """Return a read-only float64 copy of a diagonal preconditioner (entries finite, > 0)."""
    if diag is None:
        return None
    d = np.array(diag, np.float64).reshape(-1)
    if not np.all(np.isfinite(d) & (d > 0)):
        raise InputError("preconditioner entries must be finite and > 0")
    d.flags.writeable = False
    return d


def _touched(params: RenderParameter, blocks: Block) -> Block:
    """Return the blocks of the layout that have entries (an empty vector moves nothing)."""
    out = Block.NONE
    for block, n in vector_layout(params, blocks):
        out |= block if n else Block.NONE
    return out


def _as_drift(result, size: int) -> np.ndarray:
    """Return the gradient of a ``grad`` result as a drift: zeros when it is not finite."""
    g = np.asarray(result[1], np.float64).reshape(-1)
    if g.shape[0] != size:
        raise InputError(f"gradient has {g.shape[0]} entries, the flat vector {size}")
    return g if np.all(np.isfinite(g)) else np.zeros(size)


@dataclass(frozen=True, eq=False)
class MALA:
    """Preconditioned Metropolis-adjusted Langevin move on the flat vector of ``blocks``.

    ``x' = x + (eps^2 / 2) M g(x) + eps M^(1/2) z``, ``z ~ N(0, I)``, with ``g`` the
    gradient of the log posterior and ``M = diag(diag)``.

    Parameters
    ----------
    grad : callable ``(RenderParameter) -> (log_density, (d,) gradient)``
        The gradient in the layout of :func:`vector_layout` for ``blocks``. It
        must be a function of its argument alone (see Notes).
    blocks : Block
        Part of :data:`GRADIENT_BLOCKS`; ``touches`` is this.
    step : float
        ``eps`` (> 0).
    diag : (d,) float array, optional
        The diagonal preconditioner M (> 0; default ones): roughly the posterior
        variances of the entries. Its length must match the layout at call time.
    name : str
        Default ``"mala-<step>"``.

    Notes
    -----
    **Exactness.** The move is a Metropolis-Hastings proposal with density
    ``q(x'|x) = N(x'; x + eps^2/2 M g(x), eps^2 M)``, and its ``log_q_ratio`` is
    ``log q(x|x') - log q(x'|x)`` exactly, computed from ``g(x)`` and ``g(x')``
    (:func:`mala_log_q_ratio`). Any drift that is a function of the position
    alone gives a valid MH kernel (detailed balance only needs the true
    proposal densities in the ratio), so the drift may be discontinuous: the
    gradient callable does its own ray cast at each point and differentiates
    with the visibility of *that* point, which jumps where a pixel changes
    triangle. If the gradient at x' were taken with the visibility (or any
    other state) of x, the "reverse" density in the ratio would not be the
    density with which a chain at x' proposes x (that one uses x''s own
    visibility); the ratio would then be wrong, detailed balance would fail and
    the chain would converge to another distribution. A non-finite gradient is
    replaced by zero (a plain random walk step there): again a function of the
    point only. Moves are ``joint`` (one MH test on the whole posterior ratio):
    the ratio nearly cancels the change of the whole posterior, so the filter
    chain's landmark-only first test would reject uphill moves. A proposed
    ``focal_length <= 0`` is outside the prior's support and gets ratio ``-inf``
    without evaluating the gradient there.

    **Cache.** A move needs ``g(x)`` and ``g(x')``; the next move starts from x' (accepted)
    or x (rejected). Both are kept keyed by the very ``RenderParameter`` object
    (:class:`_GradientCache`; the sampler keeps ``move.params`` itself as the accepted
    state), so a chain of MALA moves evaluates one gradient per move. Copies made by
    :meth:`with_scales` share the cache (the gradient does not depend on the scales).
    """

    grad: GradFn
    blocks: Block
    step: float
    diag: np.ndarray | None = None
    name: str = ""
    touches: Block = field(init=False)
    _cache: _GradientCache = field(default_factory=_GradientCache, repr=False)

    def __post_init__(self) -> None:
        """Validate the blocks and scales, set ``touches`` and a default name."""
        object.__setattr__(self, "blocks", _check_blocks(self.blocks))
        object.__setattr__(self, "touches", self.blocks)
        check_scale(self.step, "MALA step")
        object.__setattr__(self, "diag", _checked_diag(self.diag))
        if not self.name:
            object.__setattr__(self, "name", f"mala-{self.step:g}")

    def with_scales(self, step: float, diag: np.ndarray | None = None) -> MALA:
        """Return this proposal with another step size and preconditioner (sharing its cache)."""
        name = self.name if self.name != f"mala-{self.step:g}" else ""
        return MALA(self.grad, self.blocks, step, self.diag if diag is None else diag, name,
                    self._cache)

    def drift(self, params: RenderParameter, size: int) -> np.ndarray:
        """Return the gradient at ``params`` as the move uses it (cached; 0 where not finite)."""
        return self._cache.drift(self.grad, params, size)

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        x = block_vector(params, self.blocks)
        diag = np.ones_like(x) if self.diag is None else self.diag
        if diag.shape != x.shape:
            raise InputError(f"MALA preconditioner has {diag.shape[0]} entries, the flat "
                             f"vector {x.shape[0]}")
        g = self.drift(params, x.shape[0])
        x_new = mala_mean(x, g, self.step, diag) + self.step * np.sqrt(diag) * rng.normal(
            size=x.shape[0])
        new = with_block_vector(params, self.blocks, x_new)
        touched = _touched(params, self.blocks)
        if not (new.camera.focal_length > 0.0):
            self._cache.keep((params, g))
            return Move(new, -math.inf, touched, self.name, joint=True)
        g_new = self.drift(new, x.shape[0])
        self._cache.keep((params, g), (new, g_new))
        ratio = mala_log_q_ratio(x, x_new, g, g_new, self.step, diag)
        return Move(new, ratio, touched, self.name, joint=True)


def leapfrog(x: np.ndarray, p: np.ndarray, g: np.ndarray,
             gradient: Callable[[np.ndarray], np.ndarray | None], step: float, diag: np.ndarray,
             n_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Return ``(x, p, g)`` after ``n_steps`` leapfrog steps (kinetic energy ``p^T M p / 2``).

    ``g`` is the gradient at the start ``x``; ``gradient(x)`` gives it at a new
    point, or None outside the support (the trajectory then ends: None).
    """
    p = p + 0.5 * step * g
    for i in range(n_steps):
        x = x + step * diag * p
        g = gradient(x)
        if g is None:
            return None
        p = p + (step if i + 1 < n_steps else 0.5 * step) * g
    return x, p, g


@dataclass(frozen=True, eq=False)
class HMC:
    """Hamiltonian Monte Carlo move: ``n_leapfrog`` leapfrog steps on the flat vector of ``blocks``.

    Momentum ``p ~ N(0, M^-1)``, kinetic energy ``K(p) = p^T M p / 2`` (``M = diag``,
    as for :class:`MALA`; one leapfrog step is exactly MALA's proposal),
    ``log_q_ratio = K(p) - K(p')``. Parameters as :class:`MALA`'s, plus
    ``n_leapfrog`` (>= 1) and ``jitter``: each move's step is ``eps (1 + jitter
    (2 u - 1))``, u uniform (independent of the state, so still exact), which keeps
    a fixed trajectory length from resonating with a period of the posterior.
    Each leapfrog step evaluates the gradient (its own ray cast).

    Notes
    -----
    **Exactness.** Each half kick ``p += eps/2 g(x)`` and each drift ``x += eps M p``
    is a shear with unit Jacobian as long as ``g`` is a function of the position
    alone, whatever its discontinuities (visibility jumps), so the trajectory map
    followed by a momentum flip is a volume-preserving involution and the MH test
    with ``exp(-K)`` is exact. Gradients with the visibility frozen at the
    trajectory's start would make every kick depend on ``x_0``: the reversed
    trajectory from ``x_L`` (whose kicks would use ``x_L``'s visibility) would not
    retrace the path, the map would not be an involution and the chain would
    not keep the posterior. A point with ``focal_length <= 0`` (outside the
    prior's support) ends the trajectory with ratio ``-inf``; the reversed
    trajectory meets the same point, so the rule is symmetric. The gradients at
    the two ends are cached as :class:`MALA`'s.
    """

    grad: GradFn
    blocks: Block
    step: float
    n_leapfrog: int = 5
    diag: np.ndarray | None = None
    jitter: float = 0.2
    name: str = ""
    touches: Block = field(init=False)
    _cache: _GradientCache = field(default_factory=_GradientCache, repr=False)

    def __post_init__(self) -> None:
        """Validate the blocks, scales and number of steps; set ``touches`` and a name."""
        if not 0.0 <= float(self.jitter) < 1.0:
            raise InputError(f"HMC jitter must be in [0, 1), got {self.jitter!r}")
        object.__setattr__(self, "blocks", _check_blocks(self.blocks))
        object.__setattr__(self, "touches", self.blocks)
        check_scale(self.step, "HMC step")
        if int(self.n_leapfrog) < 1:
            raise InputError(f"HMC needs n_leapfrog >= 1, got {self.n_leapfrog!r}")
        object.__setattr__(self, "n_leapfrog", int(self.n_leapfrog))
        object.__setattr__(self, "diag", _checked_diag(self.diag))
        if not self.name:
            object.__setattr__(self, "name", f"hmc-{self.n_leapfrog}x{self.step:g}")

    def with_scales(self, step: float, diag: np.ndarray | None = None,
                    n_leapfrog: int | None = None) -> HMC:
        """Return this proposal with other scales (sharing its cache)."""
        default = f"hmc-{self.n_leapfrog}x{self.step:g}"
        return HMC(self.grad, self.blocks, step,
                   self.n_leapfrog if n_leapfrog is None else n_leapfrog,
                   self.diag if diag is None else diag, self.jitter,
                   self.name if self.name != default else "", self._cache)

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        x = block_vector(params, self.blocks)
        diag = np.ones_like(x) if self.diag is None else self.diag
        if diag.shape != x.shape:
            raise InputError(f"HMC preconditioner has {diag.shape[0]} entries, the flat "
                             f"vector {x.shape[0]}")
        g = self._cache.drift(self.grad, params, x.shape[0])
        step = self.step * (1.0 + self.jitter * (2.0 * rng.random() - 1.0)) if self.jitter \
            else self.step
        p = rng.normal(size=x.shape[0]) / np.sqrt(diag)
        points = []

        def gradient(y):
            points.append(with_block_vector(params, self.blocks, y))
            if not points[-1].camera.focal_length > 0.0:
                return None
            return _as_drift(self.grad(points[-1]), x.shape[0])

        end = leapfrog(x, p, g, gradient, step, diag, self.n_leapfrog)
        touched = _touched(params, self.blocks)
        if end is None:
            self._cache.keep((params, g))
            return Move(points[-1], -math.inf, touched, self.name, joint=True)
        _, p_new, g_new = end
        self._cache.keep((params, g), (points[-1], g_new))
        ratio = 0.5 * float(np.sum(diag * p * p) - np.sum(diag * p_new * p_new))
        return Move(points[-1], ratio, touched, self.name, joint=True)
