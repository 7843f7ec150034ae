"""The albedo coefficients and the colour offsets drawn together from their Gaussian conditional.

With geometry, pose, camera, light, the colour transform's gain and contrast
and the specular exponent fixed, a rendered face pixel is affine in the albedo
coefficients ``c`` *and* in the colour transform's offsets ``o``:
``R = r0 + J c + n o`` per pixel and channel (:class:`~proposals.albedo_solver.AlbedoSystem`;
``n`` is :func:`albedo_model.shading.effects.offset_count`, 2 with the specular
image, whose transform adds the offset again). Under the N(0, I) prior of
``c``, an independent N(0, ``offset_sd``^2) prior of each offset and Gaussian
pixel noise, ``(c, o)`` given the rest is Gaussian, and
:class:`AlbedoOffsetConditional` draws both from it.

Why both at once: where a photograph pins the face's colours only weakly (a
face the model does not span: its residuals are correlated over ~150 pixels,
so the tempered likelihood counts ~100 independent pixels), a brighter or
more saturated albedo and a smaller offset render nearly the same image. The
albedo's own conditional (offsets held) and the Gaussian moves cross that
ridge slowly: on a held-out subject of the evaluation (`ambient` scene) the
region albedo means and the offsets had bulk-ESS 5-15 after 2 x 3,000 steps,
the most elongated direction of the draws (offsets with the first albedo
coefficient) 128 times the Laplace approximation's variance.

The clamp test (pixels whose render at the model's mean albedo reaches
:data:`~proposals.albedo_solver.SATURATION_LIMIT` are left out) reads the
render without its offset, so the conditional depends on none of the blocks
the move changes: it is an exact independence proposal, and the kernel's MH
test corrects what the clamp leaves.

This module imports only :mod:`albedo_model.params`, :mod:`albedo_model.render.cache_table`
and :mod:`proposals` (albedo_solver, base).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from albedo_model.params import Block
from albedo_model.render.cache_table import Kept
from proposals.albedo_solver import (
    SATURATION_LIMIT,
    AlbedoData,
    AlbedoSystem,
    albedo_system,
    independence_draw,
)
from proposals.base import Move, ProposalState, check_scale, no_move

__all__ = ["AlbedoOffsetConditional", "ContrastAlbedoExchange", "albedo_offset_conditional"]


def _kept_pixels(system: AlbedoSystem) -> tuple[np.ndarray, float] | None:
    """Rows the conditional reads (unclamped, at most ``n_points``) and the weight each carries."""
    keep = np.all(system.bright < SATURATION_LIMIT, axis=1)
    n_keep = int(keep.sum())
    if n_keep == 0:
        return None
    if n_keep > system.n_points:  # a subset: the first n_points in the fixed random order
        idx = np.flatnonzero(keep)
        idx = idx[np.argsort(system.rank[idx])[: system.n_points]]
        keep = np.zeros_like(keep)
        keep[idx] = True
        return keep, n_keep / idx.size
    return keep, 1.0


def albedo_offset_conditional(system: AlbedoSystem, sigma: float,
                              offset_sd: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Return ``(mean (k+3,), Cholesky factor L of the precision)`` of ``(c, o)`` given the rest.

    Parameters
    ----------
    system : AlbedoSystem
        The render linearised in the albedo coefficients (its ``off``, the
        current offsets' contribution, is taken out of the target again).
    sigma : float
        The likelihood's effective pixel sd.
    offset_sd : float
        Prior sd of each colour offset (mean 0).

    Returns
    -------
    tuple or None
        None when every pixel is clamped or the render has no offset.
    """
    if system.offset_count <= 0.0:
        return None
    kept = _kept_pixels(system)
    if kept is None:
        return None
    keep, subset_weight = kept
    k = system.jac.shape[2]
    jac = system.jac[keep]
    if keep.all() and subset_weight == 1.0:
        gram = system.gram
    else:
        j = jac.reshape(-1, k).astype(np.float64)
        gram = j.T @ j
    sw = (np.ones(jac.shape[0]) if system.row_weights is None
          else np.asarray(system.row_weights, np.float64)[keep])
    off = np.asarray(system.off, np.float64)
    # the photograph's rows (weighted), without the current offsets' share of the render
    target = np.asarray(system.target[keep], np.float64) - off * (1.0 - sw[:, None])
    y = target - np.asarray(system.mean[keep], np.float64)
    e = system.offset_count * sw  # d R / d o_c, the same in every channel
    jte = np.einsum("ncj,n->jc", jac, e.astype(np.float32)).astype(np.float64)
    a = subset_weight * system.weight / (sigma * sigma)
    prec = np.zeros((k + 3, k + 3))
    prec[:k, :k] = a * gram
    prec[:k, k:] = a * jte
    prec[k:, :k] = a * jte.T
    prec[k:, k:] = a * float(e @ e) * np.eye(3)
    prec[np.diag_indices(k)] += 1.0
    prec[np.arange(k, k + 3), np.arange(k, k + 3)] += 1.0 / (offset_sd * offset_sd)
    h = a * np.r_[np.einsum("ncj,nc->j", jac, y.astype(np.float32)).astype(np.float64), e @ y]
    chol = np.linalg.cholesky(prec)
    mean = np.linalg.solve(chol.T, np.linalg.solve(chol, h))
    return mean, chol


@dataclass(eq=False)
class AlbedoOffsetConditional:
    """Independence proposal ``(c', o') ~ N(m, Lambda^-1)``: albedo and colour offsets jointly.

    Parameters
    ----------
    data : AlbedoData
        The albedo system of the accepted state
        (:class:`mcmcfit.proposal_data.albedo.RenderAlbedoData`).
    sigma : float
        The likelihood's effective pixel sd.
    offset_sd : float
        Prior sd of each colour offset (the fit's prior; a mismatch costs acceptance only).
    name : str

    Notes
    -----
    ``m`` and ``Lambda`` depend only on the blocks the move keeps (geometry,
    pose, camera, light, gain and contrast), the same for the forward and the
    backward move, so the exact ratio is ``log N(x; m, Lambda^-1) - log N(x'; m,
    Lambda^-1)`` (:func:`~proposals.albedo_solver.independence_draw`).
    """

    data: AlbedoData
    sigma: float = 0.043
    offset_sd: float = 0.1
    name: str = "albedo-offset-conditional"
    touches: ClassVar[Block] = Block.ALBEDO | Block.COLOR_TRANSFORM
    _factorisation: Kept = field(default_factory=Kept, repr=False)

    def __post_init__(self) -> None:
        """Validate the scales."""
        check_scale(self.sigma, "albedo-offset conditional sigma")
        check_scale(self.offset_sd, "albedo-offset conditional offset sd")

    def conditional(self, state: ProposalState):
        """Return ``(mean (k+3,), Cholesky factor of Lambda)`` at ``state``, or None."""
        system = self.data(state)
        if system is None:
            return None
        return self._factorisation.get(
            system.key, lambda: albedo_offset_conditional(system, self.sigma, self.offset_sd))

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        c = np.asarray(params.momo.albedo, np.float64)
        cond = self.conditional(state) if c.shape[0] else None
        if cond is None:
            return no_move(params, self.name)
        ct = params.color_transform
        x = np.r_[c, np.asarray(ct.offset, np.float64)]
        new, ratio = independence_draw(x, rng.normal(0.0, 1.0, x.shape[0]), cond)
        k = c.shape[0]
        offsets = tuple(float(v) for v in new[k:])
        moved = params._replace(momo=params.momo._replace(albedo=new[:k]),
                                color_transform=ct._replace(offset=offsets))
        return Move(moved, ratio, self.touches, self.name, joint=True)


def _with_contrast(system: AlbedoSystem, mat: np.ndarray, new_mat: np.ndarray) -> AlbedoSystem:
    """Return the system under another colour matrix (``M' M^-1`` applied to every colour)."""
    t = (np.asarray(new_mat, np.float64) @ np.linalg.inv(np.asarray(mat, np.float64))
         ).astype(np.float32)
    return albedo_system(np.einsum("cd,ndj->ncj", t, system.jac), system.mean @ t.T,
                         system.bright @ t.T, system.target, system.off, system.rank,
                         system.n_points, system.weight, None,
                         offset_count=system.offset_count, row_weights=system.row_weights)


@dataclass(eq=False)
class ContrastAlbedoExchange(AlbedoOffsetConditional):
    """Step the colour contrast, redraw albedo and offsets from their conditional under it.

    Parameters
    ----------
    data : AlbedoData
    step : float
        Sd of the contrast's Gaussian step.
    sigma : float
        The likelihood's effective pixel sd.
    offset_sd : float
        Prior sd of each colour offset.
    name : str

    Notes
    -----
    The render is affine in ``(c, o)`` at any contrast ``kappa``: the colour
    matrix ``M(kappa)`` multiplies the albedo's share, so the conditional under
    ``kappa'`` comes from the current system with ``M(kappa') M(kappa)^-1``
    applied. Forward: ``kappa' = kappa + N(0, step^2)`` (symmetric; ``kappa' <= 0``
    is refused), ``(c', o') ~ N(m(kappa'), Lambda(kappa')^-1)``; backward the same
    from ``kappa'``. Ratio: ``log N((c, o); m(kappa), Lambda(kappa)^-1) - log
    N((c', o'); m(kappa'), Lambda(kappa')^-1)``. Where the model is linear the
    acceptance is the ratio of ``kappa``'s marginal posterior (albedo and
    offsets integrated out): a step along the contrast-saturation ridge that
    single-block moves cross slowly.
    """

    step: float = 0.1
    name: str = "contrast-albedo-exchange"

    def __post_init__(self) -> None:
        """Validate the scales."""
        super().__post_init__()
        check_scale(self.step, "contrast exchange step")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        ct = params.color_transform
        c = np.asarray(params.momo.albedo, np.float64)
        kappa = float(ct.contrast) + rng.normal(0.0, self.step)
        z = rng.normal(0.0, 1.0, c.shape[0] + 3)
        system = self.data(state) if c.shape[0] and ct.contrast > 0 and kappa > 0 else None
        if system is None or system.offset_count <= 0.0:
            return no_move(params, self.name)
        here = self.conditional(state)
        new_ct = ct._replace(contrast=kappa)
        there = albedo_offset_conditional(_with_contrast(system, ct.matrix(), new_ct.matrix()),
                                          self.sigma, self.offset_sd)
        if here is None or there is None:
            return no_move(params, self.name)
        new, ratio = independence_draw(np.r_[c, np.asarray(ct.offset, np.float64)], z, there, here)
        k = c.shape[0]
        moved = params._replace(
            momo=params.momo._replace(albedo=new[:k]),
            color_transform=new_ct._replace(offset=tuple(float(v) for v in new[k:])))
        return Move(moved, ratio, self.touches, self.name, joint=True)
