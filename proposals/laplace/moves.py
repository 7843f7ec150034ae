"""Moves from a Gaussian approximation of the posterior: preconditioned Crank-Nicolson, block conditionals.

A :class:`GaussianApproximation` ``N(m, S)`` of the posterior in sampling
coordinates ``u`` (:class:`~proposals.laplace.coordinates.SamplingCoordinates`) comes
from a Laplace approximation at the mode (:mod:`mcmcfit.fitting.mode`: the
Gauss-Newton precision of the image likelihood through the JAX pixel
Jacobian, plus landmarks and prior), optionally refined from warm-up draws.
Two moves use it; both are exact Metropolis-Hastings proposals whatever the
approximation (a poor one only lowers the acceptance):

* :class:`CrankNicolson` (pCN; Cotter, Roberts, Stuart & White 2013) moves every
  coordinate: ``u' = m + rho (u - m) + sqrt(1 - rho^2) L z``, ``z ~ N(0, I)``,
  ``S = L L^T``. It is reversible with respect to ``N(m, S)``, so its ratio is
  ``log N(u; m, S) - log N(u'; m, S)``; with ``rho = 0`` it is the independence
  sampler (each accepted move a fresh draw), with ``rho -> 1`` a small step.
  Where the posterior is nearly Gaussian it is accepted most of the time and
  decorrelates all ~130 coordinates at once, which single-block random walks
  cannot do along the posterior's ridges (shape-pose, focal length-distance,
  light-albedo).
* :class:`GaussianBlockConditional` redraws one block of coordinates from the
  approximation's conditional given the others, ``N(m_b - P_bb^-1 P_br (u_r - m_r),
  P_bb^-1)`` (P = S^-1): the other coordinates are unchanged, so the conditional
  is the same both ways and the ratio is that of an independence draw.

Both move the parameters as stored by moving ``u``; the ratio carries the
coordinates' ``log |dx/du|`` (:meth:`~proposals.laplace.coordinates.SamplingCoordinates.log_jacobian`).
Moves are ``joint`` (one MH test on the whole posterior ratio).

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.params`,
:mod:`proposals.base`, :mod:`proposals.gradient` (the leapfrog, the gradient
cache) and :mod:`proposals.laplace.coordinates`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block, RenderParameter
from proposals.base import Move, ProposalState, check_scale
from proposals.laplace.coordinates import SamplingCoordinates
from proposals.gradient import _GradientCache, leapfrog

__all__ = ["CrankNicolson", "GaussianApproximation", "GaussianBlockConditional", "GaussianHMC",
           "CoordinateGradient"]

#: ``grad(params) -> (log density, gradient)`` in the sampling coordinates (a function of
#: ``params`` alone; :class:`GaussianHMC`).
CoordinateGradient = Callable[[RenderParameter], tuple[float, np.ndarray]]


@dataclass(frozen=True, eq=False)
class GaussianApproximation:
    """``N(mean, covariance)`` in sampling coordinates, held as the Cholesky factors it needs.

    Parameters
    ----------
    mean : (d,) float array
    precision : (d, d) float array
        Symmetric positive definite (the Laplace approximation's negative Hessian).

    Attributes
    ----------
    chol_cov : (d, d) lower-triangular L with ``L L^T = precision^-1``.
    """

    mean: np.ndarray
    precision: np.ndarray
    chol_cov: np.ndarray = field(init=False, repr=False)
    _chol_prec: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Validate and factorise (raises InputError when the precision is not positive definite)."""
        m = np.array(self.mean, np.float64).reshape(-1)
        p = np.array(self.precision, np.float64)
        if p.shape != (m.size, m.size) or not np.all(np.isfinite(p)) or not np.all(
                np.isfinite(m)):
            raise InputError("Gaussian approximation: mean and precision must be finite, "
                             f"(d,) and (d, d); got {m.shape} and {p.shape}")
        p = 0.5 * (p + p.T)
        try:
            cp = np.linalg.cholesky(p)
        except np.linalg.LinAlgError:
            raise InputError("Gaussian approximation: precision is not positive definite") \
                from None
        # S = P^-1 = (C C^T)^-1 = C^-T C^-1; a lower factor of S is the flipped factor of P
        inv = np.linalg.solve(cp, np.eye(m.size))  # C^-1
        s = inv.T @ inv
        lc = np.linalg.cholesky(0.5 * (s + s.T))
        for name, value in (("mean", m), ("precision", p), ("chol_cov", lc), ("_chol_prec", cp)):
            value.flags.writeable = False
            object.__setattr__(self, name, value)

    @property
    def size(self) -> int:
        """Dimension d."""
        return int(self.mean.size)

    def covariance(self) -> np.ndarray:
        """Return the covariance ``L L^T``."""
        return self.chol_cov @ self.chol_cov.T

    def log_density(self, u: np.ndarray) -> float:
        """Return ``log N(u; m, S)`` up to the (state-independent) normaliser."""
        z = self._chol_prec.T @ (np.asarray(u, np.float64) - self.mean)
        return -0.5 * float(z @ z)

    def draw(self, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
        """Return a draw of ``N(m, scale^2 S)``."""
        return self.mean + scale * (self.chol_cov @ rng.normal(size=self.size))

    def widened(self, mask: np.ndarray, factor: float) -> GaussianApproximation:
        """Return the approximation with the sds of the ``mask`` coordinates times ``factor``.

        The precision becomes ``D P D`` with ``D = diag(1 / factor on mask, 1 elsewhere)``:
        the block's covariance is scaled by ``factor^2``, its cross-covariances by
        ``factor``, its conditional sds given the rest by ``factor``.
        """
        if not (math.isfinite(factor) and factor > 0.0):
            raise InputError(f"widening factor must be positive, got {factor!r}")
        d = np.where(np.asarray(mask, bool).reshape(-1), 1.0 / factor, 1.0)
        return GaussianApproximation(self.mean, self.precision * np.outer(d, d))


def _check(coords: SamplingCoordinates, approx: GaussianApproximation) -> None:
    if coords.size != approx.size:
        raise InputError(f"Gaussian approximation has {approx.size} coordinates, the "
                         f"sampling coordinates {coords.size}")


@dataclass(frozen=True, eq=False)
class CrankNicolson:
    """Preconditioned Crank-Nicolson move about a Gaussian approximation (see the module notes).

    Parameters
    ----------
    coords : SamplingCoordinates
    approx : GaussianApproximation
    rho : float in [0, 1)
        Autoregression coefficient (0: independence sampler).
    name : str
        Default ``"pcn-<rho>"``.
    """

    coords: SamplingCoordinates
    approx: GaussianApproximation
    rho: float = 0.5
    name: str = ""
    touches: Block = field(init=False)

    def __post_init__(self) -> None:
        """Validate ``rho`` and the dimensions; set ``touches`` and the name."""
        _check(self.coords, self.approx)
        if not (math.isfinite(self.rho) and 0.0 <= self.rho < 1.0):
            raise InputError(f"pCN rho must be in [0, 1), got {self.rho!r}")
        object.__setattr__(self, "touches", self.coords.touches)
        if not self.name:
            object.__setattr__(self, "name", f"pcn-{self.rho:.2f}")

    def with_rho(self, rho: float) -> CrankNicolson:
        """Return this move with another ``rho`` (same name)."""
        return CrankNicolson(self.coords, self.approx, rho, self.name)

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        c, a = self.coords, self.approx
        u = c.u_of(state.params)
        u_new = a.mean + self.rho * (u - a.mean) + math.sqrt(1.0 - self.rho ** 2) * (
            a.chol_cov @ rng.normal(size=a.size))
        ratio = (a.log_density(u) - a.log_density(u_new)
                 + c.log_jacobian(u_new) - c.log_jacobian(u))
        return Move(c.params_of(u_new, state.params), ratio, self.touches, self.name,
                    joint=True)


@dataclass(frozen=True, eq=False)
class GaussianBlockConditional:
    """Redraw the coordinates of ``mask`` from the approximation's conditional given the rest.

    Parameters
    ----------
    coords : SamplingCoordinates
    approx : GaussianApproximation
    mask : (d,) bool
        The coordinates the move redraws (a non-empty subset).
    name : str
    rho : float in [0, 1)
        Crank-Nicolson autoregression within the block: ``u_b' = m_b + rho (u_b -
        m_b) + sqrt(1 - rho^2) L_b z`` with ``m_b``, ``L_b L_b^T`` the conditional's
        mean and covariance (0: an independent draw from the conditional). It is
        reversible with respect to the conditional, which the other
        coordinates (unchanged) fix, so the ratio is still
        ``log N_b(u_b) - log N_b(u_b')``.
    """

    coords: SamplingCoordinates
    approx: GaussianApproximation
    mask: np.ndarray
    name: str = "gaussian-block"
    rho: float = 0.0
    touches: Block = field(init=False)
    _idx: np.ndarray = field(init=False, repr=False)
    _rest: np.ndarray = field(init=False, repr=False)
    _chol_pbb: np.ndarray = field(init=False, repr=False)
    _coupling: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Factorise the block's conditional precision and set ``touches``."""
        _check(self.coords, self.approx)
        if not (math.isfinite(self.rho) and 0.0 <= self.rho < 1.0):
            raise InputError(f"block-conditional rho must be in [0, 1), got {self.rho!r}")
        mask = np.asarray(self.mask, bool).reshape(-1)
        if mask.shape[0] != self.approx.size or not mask.any():
            raise InputError("block-conditional mask must select some of the coordinates")
        idx, rest = np.flatnonzero(mask), np.flatnonzero(~mask)
        p = self.approx.precision
        chol = np.linalg.cholesky(p[np.ix_(idx, idx)])
        coupling = np.linalg.solve(chol.T, np.linalg.solve(chol, p[np.ix_(idx, rest)]))
        for name, value in (("_idx", idx), ("_rest", rest), ("_chol_pbb", chol),
                            ("_coupling", coupling)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "touches", self.coords.blocks_of(mask))

    def _log_density(self, ub: np.ndarray, mean: np.ndarray) -> float:
        z = self._chol_pbb.T @ (ub - mean)
        return -0.5 * float(z @ z)

    def with_rho(self, rho: float) -> GaussianBlockConditional:
        """Return this move with another ``rho`` (same block and name)."""
        return GaussianBlockConditional(self.coords, self.approx, self.mask, self.name, rho)

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        c, a = self.coords, self.approx
        u = c.u_of(state.params)
        mean = a.mean[self._idx] - self._coupling @ (u[self._rest] - a.mean[self._rest])
        z = rng.normal(size=self._idx.size)
        ub = (mean + self.rho * (u[self._idx] - mean)
              + math.sqrt(1.0 - self.rho ** 2) * np.linalg.solve(self._chol_pbb.T, z))
        u_new = u.copy()
        u_new[self._idx] = ub
        ratio = (self._log_density(u[self._idx], mean) - self._log_density(ub, mean)
                 + c.log_jacobian(u_new) - c.log_jacobian(u))
        return Move(c.params_of(u_new, state.params), ratio, self.touches, self.name,
                    joint=True)


@dataclass(frozen=True, eq=False)
class GaussianHMC:
    """Hamiltonian Monte Carlo in the coordinates the Gaussian approximation whitens.

    With ``u = m + L z`` (``L L^T`` the approximation's covariance) the
    approximation is ``N(0, I)`` in ``z``: the mass matrix is the
    approximation's precision, so the posterior's ridges (shape against pose,
    light against albedo: canonical correlations above 0.99 at a sharp
    likelihood) become round, and the true gradient corrects what the
    approximation gets wrong. ``n_leapfrog`` steps of size ``step`` (jittered
    by ``+-jitter``, independently of the state), momenta ``N(0, I)``, ratio
    ``K(p) - K(p')`` plus the coordinates' ``log |dx/du|`` change.

    Parameters
    ----------
    coords : SamplingCoordinates
    approx : GaussianApproximation
    grad : callable ``(params) -> (log_density, gradient in u)``
        A function of its argument alone (see Notes), e.g.
        :func:`mcmcfit.targets.curvature.coordinate_gradient`.
    step : float
        Leapfrog step in whitened units (about 1 where the approximation holds).
    n_leapfrog : int
    jitter : float in [0, 1)
    random_steps : bool
        Draw each move's number of steps uniformly from 1 to ``2 n_leapfrog - 1``
        (mean ``n_leapfrog``): no trajectory length is the same for every move, so
        no direction is carried a fixed fraction of its period each time
        (Neal 2011, section 5.4.2.2).
    name : str

    Notes
    -----
    **Exactness** (as :class:`proposals.gradient.HMC`): each kick and drift is a
    shear with unit Jacobian as long as the gradient depends on the position
    alone. The gradient a trajectory uses at a point is computed from a ray
    cast *at that point* (the triangles its rays see there), never from the
    visibility of the trajectory's start, so the leapfrog map followed by a
    momentum flip is a volume-preserving involution and the MH test with
    ``exp(-K)`` and the exact ray-cast posterior keeps the posterior. The
    whitening ``u = m + L z`` is a fixed linear map (constant Jacobian). A
    point outside the parameters' domain or whose density or gradient is not
    finite (a diverged trajectory) ends it with ratio -inf (a function of the
    point alone: the reversed trajectory meets the same point). The step size and the
    number of steps are drawn independently of the state, so the kernel is a
    mixture of such reversible kernels. Gradients at the two ends are cached by
    ``params`` object (the next move starts from one of them).
    """

    coords: SamplingCoordinates
    approx: GaussianApproximation
    grad: CoordinateGradient
    step: float = 0.8
    n_leapfrog: int = 2
    jitter: float = 0.2
    name: str = "hmc"
    random_steps: bool = False
    touches: Block = field(init=False)
    _cache: _GradientCache = field(default_factory=_GradientCache, repr=False)

    def __post_init__(self) -> None:
        """Validate the scales; set ``touches``."""
        _check(self.coords, self.approx)
        check_scale(self.step, "HMC step")
        if int(self.n_leapfrog) < 1:
            raise InputError(f"HMC needs n_leapfrog >= 1, got {self.n_leapfrog!r}")
        if not 0.0 <= float(self.jitter) < 1.0:
            raise InputError(f"HMC jitter must be in [0, 1), got {self.jitter!r}")
        object.__setattr__(self, "n_leapfrog", int(self.n_leapfrog))
        object.__setattr__(self, "touches", self.coords.touches)

    def with_step(self, step: float) -> GaussianHMC:
        """Return this move with another step size (sharing its gradient cache)."""
        return GaussianHMC(self.coords, self.approx, self.grad, step, self.n_leapfrog,
                           self.jitter, self.name, self.random_steps, self._cache)

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        c, a = self.coords, self.approx
        params = state.params
        u = c.u_of(params)
        z = np.linalg.solve(a.chol_cov, u - a.mean)
        g_u = self._cache.drift(self.grad, params, u.size)
        if not np.any(g_u):
            return Move(params, -math.inf, self.touches, self.name, joint=True)
        step = self.step * (1.0 + self.jitter * (2.0 * rng.random() - 1.0)) if self.jitter \
            else self.step
        n_steps = int(rng.integers(1, 2 * self.n_leapfrog)) if self.random_steps \
            else self.n_leapfrog
        p = rng.normal(size=z.size)
        points: list[RenderParameter] = []
        grads: list[np.ndarray] = []

        def gradient(zz):
            uu = a.mean + a.chol_cov @ zz
            if not np.all(np.isfinite(uu)):
                return None
            if not math.isfinite(c.log_jacobian(uu)):
                return None  # outside the coordinates' domain (e.g. the face behind the camera)
            points.append(c.params_of(uu, params))
            try:
                value, raw = self.grad(points[-1])
            except (InputError, ValueError, ArithmeticError):
                return None  # outside the parameters' domain: a diverged trajectory
            raw = np.asarray(raw, np.float64)
            if not (np.isfinite(value) and np.all(np.isfinite(raw))):
                return None
            grads.append(raw)
            return a.chol_cov.T @ raw

        with np.errstate(all="ignore"):  # a diverging trajectory ends below (-inf)
            end = leapfrog(z, p, a.chol_cov.T @ g_u, gradient, step, np.ones(z.size),
                           n_steps)
        if end is None:  # refused: the kernel rejects a -inf move without evaluating its point
            self._cache.keep((params, g_u))
            return Move(params, -math.inf, self.touches, self.name, joint=True)
        z_new, p_new, _ = end
        self._cache.keep((params, g_u), (points[-1], grads[-1]))
        u_new = a.mean + a.chol_cov @ z_new
        ratio = (0.5 * float(p @ p - p_new @ p_new)
                 + c.log_jacobian(u_new) - c.log_jacobian(u))
        return Move(points[-1], ratio, self.touches, self.name, joint=True)
