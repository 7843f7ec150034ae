"""Albedo proposals from the albedo's Gaussian conditional: a Gibbs-like draw, a light exchange.

With geometry, pose, camera, light and colour transform fixed, a rendered
pixel is affine in the (shared) albedo coefficients c: ``R = M (l s m + l s J c) + o``
per pixel (``l`` the cached light transport, ``J`` the interpolated albedo
bases, ``M``, ``o`` the colour transform, ``s`` a scale of the whole SH light,
which the light transport is linear in). With Gaussian pixel noise and the
N(0, 1) prior, the conditional of c is Gaussian with precision
``Lambda = I + w A^T A / sigma^2`` and mean ``Lambda^-1 w A^T (t - r0) / sigma^2``
(A, r0 the affine map's matrix and offset). The face mask does not depend on
c, so the background terms cancel and this is the exact conditional of the
independent-pixel posterior, up to the clamp at 1 (pixels whose render at a
reference albedo reaches 0.97 are left out) and ``w``, the factor by which a
pixel subset stands in for all face pixels.

* :class:`AlbedoConditional` draws every albedo coefficient from it (light kept).
* :class:`LightAlbedoExchange` scales the light by ``s = exp(N(0, log_sigma))``
  and draws the albedo from its conditional under the new light: a move along
  the light-intensity x albedo ridge, which single-block moves cross only slowly.

Both are ``joint`` moves (one MH test on the whole posterior ratio).

This module imports only :mod:`albedo_model.params` and :mod:`proposals.base`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar, NamedTuple

import numpy as np

from albedo_model.params import Block, SHLight
from albedo_model.render.cache_table import Kept
from proposals.base import Move, ProposalState, check_scale, no_move

__all__ = ["SATURATION_LIMIT", "AlbedoConditional", "AlbedoData", "AlbedoSystem",
           "LightAlbedoExchange", "albedo_system", "conditional_terms", "independence_draw",
           "solve_conditional"]

#: Linear intensity at and above which a pixel counts as clipped (by the camera in a
#: target, by the clamp at 1 in a render).
SATURATION_LIMIT = 0.97


class AlbedoSystem(NamedTuple):
    """The render at N face pixels as an affine function of the albedo coefficients.

    Per pixel (rows of 3 channels): ``R = s (jac c + mean) + off`` for the light
    scaled by s, colour transform included.

    Attributes
    ----------
    jac : (N, 3, k) float32
    mean : (N, 3) float32
    bright : (N, 3) float32
        The render at a reference albedo without ``off``, for the clamp test.
    target : (N, 3) float32
        Target colours (linear).
    off : (3,) float32
        The colour transform's offset.
    rank : (N,) int
        Position of each pixel in a fixed random order (subset selection).
    n_points : int
        Pixels used at most.
    gram : (k, k) float64
        ``J^T J`` over all N pixels (J = jac as (3N, k)).
    jt_target, jt_mean, jt_off : (k,) float64
        ``J^T`` times the targets, the means and the offsets over all N pixels.
    weight : float
        How many face pixels each of the N stands for (N is a subset of the face).
    key : tuple or None
        Identifies the system among those of one data source (the version stamps
        of the blocks it reads, :mod:`albedo_model.render.cache_table`): the
        proposals keep the factorisation of the conditional while it is unchanged.
        None: never reused.
    offset_count : float
        How often the colour transform's offset enters a pixel (``off`` is this
        times the offsets; 0 when the render has no colour transform).
    row_weights : (N,) float or None
        Square roots of fixed per-pixel weights the rows (``jac``, ``mean`` and
        ``target - off``) were scaled by; None: unweighted.
    """

    jac: np.ndarray
    mean: np.ndarray
    bright: np.ndarray
    target: np.ndarray
    off: np.ndarray
    rank: np.ndarray
    n_points: int
    gram: np.ndarray
    jt_target: np.ndarray
    jt_mean: np.ndarray
    jt_off: np.ndarray
    weight: float = 1.0
    key: tuple | None = None
    offset_count: float = 1.0
    row_weights: np.ndarray | None = None


def _normal_terms(jac, mean, target, off):
    k = jac.shape[2]
    j = jac.reshape(-1, k)
    return ((j.T @ j).astype(np.float64), (j.T @ target.reshape(-1)).astype(np.float64),
            (j.T @ mean.reshape(-1)).astype(np.float64),
            (jac.sum(0).T @ off).astype(np.float64))


def albedo_system(jac, mean, bright, target, off, rank, n_points: int,
                  weight: float = 1.0, key: tuple | None = None, *, offset_count: float = 1.0,
                  row_weights: np.ndarray | None = None) -> AlbedoSystem:
    """Return an :class:`AlbedoSystem` with its normal-equation terms precomputed."""
    return AlbedoSystem(jac, mean, bright, target, off, rank, int(n_points),
                        *_normal_terms(jac, mean, target, off), float(weight), key,
                        float(offset_count), row_weights)


#: ``data(state) -> AlbedoSystem or None`` of the accepted state (its ``params`` and
#: ``render_state``); the same ``key`` for states that differ only in the albedo
#: coefficients.
AlbedoData = Callable[[ProposalState], "AlbedoSystem | None"]


def conditional_terms(system: AlbedoSystem, scale: float,
                      sigma: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Return the likelihood's share of the conditional for the light scaled by ``scale``.

    Returns ``(P, h)``: the precision the pixels add to the prior's identity,
    ``w s^2 A^T A / sigma^2`` (k, k), and the information vector
    ``w s A^T (t - s r0 - o) / sigma^2`` (k,); None when every pixel is clamped.
    Images with independent noise add their terms (:func:`solve_conditional`).
    Pixels whose reference render reaches the clamp are dropped; their
    contribution is subtracted from the precomputed normal-equation terms.
    """
    keep = np.all(scale * system.bright + system.off < SATURATION_LIMIT, axis=1)
    n_keep = int(keep.sum())
    if n_keep == 0:
        return None
    if n_keep > system.n_points:  # a subset: recompute over it
        idx = np.flatnonzero(keep)
        idx = idx[np.argsort(system.rank[idx])[: system.n_points]]
        gram, jt_t, jt_m, jt_o = _normal_terms(system.jac[idx], system.mean[idx],
                                               system.target[idx], system.off)
        weight = n_keep / idx.size
    else:
        gram, jt_t, jt_m, jt_o = system.gram, system.jt_target, system.jt_mean, system.jt_off
        drop = ~keep
        if drop.any():
            g, t, m, o = _normal_terms(system.jac[drop], system.mean[drop],
                                       system.target[drop], system.off)
            gram, jt_t, jt_m, jt_o = gram - g, jt_t - t, jt_m - m, jt_o - o
        weight = 1.0
    a = weight * system.weight / (sigma * sigma)
    return (a * scale * scale) * gram, (a * scale) * (jt_t - scale * jt_m - jt_o)


def solve_conditional(precision: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(mean (k,), cholesky L of I + precision)``: the conditional under N(0, I)."""
    lam = np.eye(len(h)) + precision
    chol = np.linalg.cholesky(lam)
    mean = np.linalg.solve(chol.T, np.linalg.solve(chol, h))
    return mean, chol


def _conditional(system: AlbedoSystem, scale: float, sigma: float):
    """``(mean (k,), cholesky L of the precision (k, k))`` for the light scaled by ``scale``."""
    terms = conditional_terms(system, scale, sigma)
    return None if terms is None else solve_conditional(*terms)


def _log_density_terms(c: np.ndarray, cond) -> float:
    """``-(c - m)^T Lambda (c - m) / 2 + log det L`` (a Gaussian log density up to 2 pi)."""
    mean, chol = cond
    d = chol.T @ (c - mean)
    return -0.5 * float(d @ d) + float(np.sum(np.log(np.diag(chol))))


def independence_draw(x: np.ndarray, z: np.ndarray, cond,
                      back=None) -> tuple[np.ndarray, float]:
    """Draw ``x' ~ N(m, Lambda^-1)`` from standard normals ``z``; return ``(x', log ratio)``.

    ``cond`` is ``(m, L)`` with ``L`` the Cholesky factor of the precision; the
    ratio ``log N(x; back) - log N(x'; cond)`` is that of an independence
    proposal when ``back`` is None (the same mean and precision both ways), and
    of an exchange move when ``back`` is the conditional the reverse move draws
    from (e.g. at the state's own contrast or light scale).
    """
    mean, chol = cond
    new = mean + np.linalg.solve(chol.T, z)  # (x' - m)^T Lambda (x' - m) = z^T z
    ratio = _log_density_terms(x, cond if back is None else back) + 0.5 * float(z @ z) - float(
        np.sum(np.log(np.diag(chol))))
    return new, ratio


@dataclass(eq=False)
class AlbedoConditional:
    """Independence proposal ``c' ~ N(m, Lambda^-1)`` from the albedo's Gaussian conditional.

    Parameters
    ----------
    data : AlbedoData
    sigma : float
        Pixel noise of the likelihood (linear units).
    name : str

    Notes
    -----
    ``m`` and ``Lambda`` depend only on the blocks the move keeps, so they are
    the same for the forward and the backward move, and the exact ratio is
    ``log N(c; m, Lambda^-1) - log N(c'; m, Lambda^-1)``. The factorisation is
    kept while the system's ``key`` is unchanged (it changes only when the
    geometry, light or colour transform does).
    """

    data: AlbedoData
    sigma: float = 0.043
    name: str = "albedo-conditional"
    touches: ClassVar[Block] = Block.ALBEDO
    _factorisation: Kept = field(default_factory=Kept, repr=False)

    def __post_init__(self) -> None:
        """Validate ``sigma``."""
        check_scale(self.sigma, "albedo conditional sigma")

    def conditional(self, state: ProposalState):
        """Return ``(mean (k,), cholesky factor L of Lambda (k, k))`` at ``state``, or None."""
        system = self.data(state)
        if system is None:
            return None
        return self._factorisation.get(system.key, lambda: _conditional(system, 1.0, self.sigma))

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        c = np.asarray(params.momo.albedo, np.float64)
        z = rng.normal(0.0, 1.0, c.shape[0])
        cond = self.conditional(state) if c.shape[0] else None
        if cond is None:
            return no_move(params, self.name)
        new, ratio = independence_draw(c, z, cond)
        return Move(params._replace(momo=params.momo._replace(albedo=new)), ratio, Block.ALBEDO,
                    self.name, joint=True)


@dataclass(eq=False)
class LightAlbedoExchange:
    """Scale the SH light by ``s = exp(N(0, log_sigma))``, redraw the albedo from its conditional.

    Parameters
    ----------
    data : AlbedoData
    log_sigma : float
        Standard deviation of ``log s``.
    sigma : float
        Pixel noise of the likelihood.
    name : str

    Notes
    -----
    Forward: ``L' = s L`` (density ``phi(log s) / s^n`` in L' along the ray,
    n = 27 coefficients, as :class:`~proposals.light.SHIntensity`), then
    ``c' ~ N(m(L'), Lambda(L')^-1)``; backward: ``1/s`` and ``c ~ N(m(L), Lambda(L)^-1)``.
    The light transport is linear in L, so the conditional under ``L'`` comes
    from the current data with the scale applied. Ratio:
    ``n log s + log N(c; m(L), Lambda(L)^-1) - log N(c'; m(L'), Lambda(L')^-1)``.
    """

    data: AlbedoData
    log_sigma: float = 0.05
    sigma: float = 0.043
    name: str = ""
    touches: ClassVar[Block] = Block.ALBEDO | Block.LIGHT
    _factorisation: Kept = field(default_factory=Kept, repr=False)

    def __post_init__(self) -> None:
        """Validate the scales and name the proposal after ``log_sigma`` if unnamed."""
        check_scale(self.log_sigma, "light-albedo exchange log sigma")
        check_scale(self.sigma, "light-albedo exchange sigma")
        if not self.name:
            self.name = f"light-albedo-{self.log_sigma:g}"

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        c = np.asarray(params.momo.albedo, np.float64)
        log_s = rng.normal(0.0, self.log_sigma)
        z = rng.normal(0.0, 1.0, c.shape[0])
        L = np.asarray(params.environment_map.coefficients, np.float64)
        system = self.data(state) if c.shape[0] and np.any(L) else None
        if system is None:
            return no_move(params, self.name)
        here = self._factorisation.get(system.key,
                                       lambda: _conditional(system, 1.0, self.sigma))
        there = _conditional(system, float(np.exp(log_s)), self.sigma)
        if here is None or there is None:
            return no_move(params, self.name)
        new, ratio = independence_draw(c, z, there, here)
        ratio += L.size * log_s
        moved = params._replace(environment_map=SHLight(L * np.exp(log_s)),
                                momo=params.momo._replace(albedo=new))
        return Move(moved, ratio, Block.ALBEDO | Block.LIGHT, self.name, joint=True)
