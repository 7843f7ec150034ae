"""Posterior and posterior predictive summaries of per-vertex albedo from coefficient samples.

An albedo PCA part is linear in its coefficients, so the posterior mean and
standard deviation of every vertex colour follow exactly from the mean and
covariance of the coefficient samples (no per-sample instances needed); the
credible interval bounds need the samples and are computed in vertex blocks to
bound memory.

Coefficient-only and predictive. The coefficients' posterior describes only the
part of a face's albedo inside the model's span; a real face also differs from
the model outside it. When the part carries a residual variance ``r`` (per
vertex and channel, estimated out of sample when the model was built; see
:attr:`albedo_model.pca.PCAPart.residual_variance`), the summaries are those of
the posterior *predictive* ``x = mu + W c + e`` with ``e ~ N(0, diag(r))``
independent of ``c``: the mean is unchanged, the variance is ``Var[W c] + r``
(exact), and the interval bounds are quantiles of the mixture of
``N(mu + W c_s, r)`` over the samples ``c_s``, by Monte Carlo: every sample is
repeated ``ceil(min_draws / S)`` times with its own normal draw of ``e``. The
coefficient-only summaries are always kept beside them. Without a residual
variance (AlbedoMM and BFM files) the two are the same and ``predictive`` is
False.

This module imports only :mod:`albedo_model.errors` and :mod:`albedo_model.pca`.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.pca import PCAPart

__all__ = ["QUANTILE_DRAWS", "AlbedoPosterior", "albedo_posterior", "row_quantiles",
           "visible_vertices"]

#: Elements of one block of Monte Carlo draws (draws x rows), about 32 MB of float64.
BLOCK_ELEMENTS = 1 << 22


class AlbedoPosterior(NamedTuple):
    """Per-vertex posterior of one albedo part, each (n, 3) float32 linear sRGB.

    Attributes
    ----------
    mean : posterior mean (the same for the predictive)
    std : standard deviation, predictive when ``residual_std`` is given
    lo, hi : bounds of the central interval, predictive when ``residual_std`` is given
    level : the interval's probability (e.g. 0.9 for 5 % / 95 %)
    coef_std, coef_lo, coef_hi : the coefficient-only std and interval (None: equal
        to ``std``, ``lo``, ``hi``)
    residual_std : square root of the model's residual variance, or None when the
        model has none (the summaries are then coefficient-only)
    """

    mean: np.ndarray
    std: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    level: float
    coef_std: np.ndarray | None = None
    coef_lo: np.ndarray | None = None
    coef_hi: np.ndarray | None = None
    residual_std: np.ndarray | None = None

    @property
    def predictive(self) -> bool:
        """Whether ``std``, ``lo`` and ``hi`` include the model's residual variance."""
        return self.residual_std is not None

    def coefficient_only(self) -> AlbedoPosterior:
        """Return the summaries of the coefficients' posterior alone (``self`` if not predictive)."""
        if self.coef_std is None:
            return self._replace(residual_std=None)
        return AlbedoPosterior(self.mean, self.coef_std, self.coef_lo, self.coef_hi, self.level,
                               residual_std=None)


#: Samples the interval bounds are read from at most (:func:`albedo_posterior`).
QUANTILE_DRAWS = 4000


def row_quantiles(x: np.ndarray, q: list[float]) -> list[np.ndarray]:
    """``np.quantile(x, q, axis=1)`` (linear interpolation) by one partial sort of each row."""
    n = x.shape[1]
    pos = [(n - 1) * p for p in q]
    below = [int(np.floor(h)) for h in pos]
    kth = sorted({k for b in below for k in (b, min(b + 1, n - 1))})
    part = np.partition(x, kth, axis=1)
    return [part[:, b] + (h - b) * (part[:, min(b + 1, n - 1)] - part[:, b])
            for h, b in zip(pos, below)]


def _check(part: PCAPart, c: np.ndarray, level: float) -> None:
    if c.ndim != 2 or c.shape[0] < 1:
        raise InputError(f"coefficient samples must be (S, j) with S >= 1, got shape {c.shape}")
    if c.shape[1] > part.rank:
        raise InputError(f"{c.shape[1]} coefficients for a rank-{part.rank} part")
    if not 0 < level < 1:
        raise InputError(f"level must be in (0, 1), got {level}")


def albedo_posterior(part: PCAPart, coefficients: np.ndarray, *, level: float = 0.9,
                     block_rows: int = 8192, predictive: bool = True,
                     rng: np.random.Generator | None = None,
                     min_draws: int = 1000, max_draws: int = QUANTILE_DRAWS,
                     threads: int | None = None) -> AlbedoPosterior:
    """Posterior (predictive) mean, std and central interval of ``part``'s instance.

    Parameters
    ----------
    part : PCAPart
        Albedo part of dimension 3n (interleaved RGB per vertex).
    coefficients : (S, j) float array
        Posterior samples of the part's coefficients (j <= rank; missing ones
        are zero, as in every instance).
    level : float
        Probability of the central interval (0.9 gives the 5 % and 95 % quantiles).
    block_rows : int
        Rows of the data vector per block when computing quantiles.
    predictive : bool
        Add the part's residual variance when it has one (default); False gives
        the coefficient-only summaries whatever the part holds.
    rng : numpy.random.Generator, optional
        Draws of the residual for the predictive quantiles (default: seed 0, so
        that a fit's outputs are reproducible).
    min_draws : int
        Least number of Monte Carlo draws per row for the predictive quantiles.
    max_draws : int
        Most samples the interval bounds are read from: more are thinned
        evenly (the mean and std always use every sample).
    threads : int, optional
        Threads the row blocks are summarised in (default: min(2, CPUs)).
        Each block draws its residuals from its own stream spawned from
        ``rng``, so the result does not depend on the thread count.

    Returns
    -------
    AlbedoPosterior

    Notes
    -----
    With ``x = mu + W c`` (``W = U diag(sqrt(lambda))``): ``E[x] = mu + W E[c]`` and
    ``Var[x_i] = W_i Cov[c] W_i^T``, evaluated as ``sum((W C) * W, axis=1)``; the
    predictive adds ``r_i``. With 1,000 draws the Monte Carlo error of a 5 %
    bound is about 7 % of the predictive standard deviation (unbiased), smaller
    than that of the chain's own samples, which are autocorrelated. For the
    same reason the bounds are read from at most ``max_draws`` evenly thinned
    samples: a chain whose slowest quantities have a few hundred effective
    samples in 20,000 draws loses next to nothing (the bound of a 4,000-draw
    subset has a Monte Carlo sd of ~3 % of the posterior sd), and the partial
    sorts that dominate writing a fit's outputs take a fifth of the time. The
    draws of the bounds are formed in float32 (the bounds are stored as
    float32; the mean and std are float64).
    """
    c = np.asarray(coefficients, np.float64)
    _check(part, c, level)
    j = c.shape[1]
    w = part.scaled_basis[:, :j].astype(np.float64)
    mean = part.mean.astype(np.float64) + w @ c.mean(0)
    cov = np.cov(c, rowvar=False, ddof=0).reshape(j, j) if c.shape[0] > 1 else np.zeros((j, j))
    var = np.maximum(np.einsum("ij,ij->i", w @ cov, w), 0.0)
    residual = part.residual_variance if predictive else None
    q = [(1 - level) / 2, 1 - (1 - level) / 2]
    lo, hi = np.empty(part.dim), np.empty(part.dim)
    if c.shape[0] > max_draws:
        c = c[np.unique(np.linspace(0, c.shape[0] - 1, max_draws).round().astype(np.int64))]
    ct = np.ascontiguousarray(c.T, np.float32)
    w32, base = w.astype(np.float32), part.mean.astype(np.float32)
    f32 = lambda a: a.reshape(-1, 3).astype(np.float32)
    if residual is None:
        def coefficient_block(sl: slice) -> None:
            lo[sl], hi[sl] = row_quantiles(base[sl, None] + w32[sl] @ ct, q)  # (rows, S)

        _each_block(coefficient_block, part.dim, block_rows, threads)
        return AlbedoPosterior(f32(mean), f32(np.sqrt(var)), f32(lo), f32(hi), float(level))
    r = residual.astype(np.float64)
    rng = np.random.default_rng(0) if rng is None else rng
    reps = max(1, math.ceil(min_draws / c.shape[0]))
    rows = max(1, min(block_rows, BLOCK_ELEMENTS // (reps * c.shape[0])))
    streams = dict(zip(range(0, part.dim, rows), rng.spawn(-(-part.dim // rows))))
    r_sd = np.sqrt(r).astype(np.float32)
    c_lo, c_hi = np.empty(part.dim), np.empty(part.dim)

    def predictive_block(sl: slice) -> None:
        x = base[sl, None] + w32[sl] @ ct                      # (rows, S)
        c_lo[sl], c_hi[sl] = row_quantiles(x, q)
        draws = streams[sl.start].standard_normal((x.shape[0], x.shape[1], reps),
                                                  dtype=np.float32)
        draws *= r_sd[sl, None, None]
        draws += x[:, :, None]
        lo[sl], hi[sl] = row_quantiles(draws.reshape(x.shape[0], -1), q)

    _each_block(predictive_block, part.dim, rows, threads)
    return AlbedoPosterior(f32(mean), f32(np.sqrt(var + r)), f32(lo), f32(hi), float(level),
                           coef_std=f32(np.sqrt(var)), coef_lo=f32(c_lo), coef_hi=f32(c_hi),
                           residual_std=f32(np.sqrt(r)))


def _each_block(work, dim: int, rows: int, threads: int | None) -> None:
    """Call ``work(slice)`` on consecutive row blocks, in threads (NumPy's sorts release the GIL)."""
    blocks = [slice(start, min(start + rows, dim)) for start in range(0, dim, rows)]
    threads = min(2, os.cpu_count() or 1) if threads is None else max(1, int(threads))
    if threads == 1 or len(blocks) == 1:
        for sl in blocks:
            work(sl)
        return
    with ThreadPoolExecutor(threads) as pool:
        for _ in pool.map(work, blocks):
            pass


def visible_vertices(renderer, state) -> np.ndarray:
    """Vertices of the state's instance seen by the camera (front-facing and not occluded).

    Parameters
    ----------
    renderer : albedo_model.render.renderer.Renderer
    state : albedo_model.render.renderer.RenderState

    Returns
    -------
    (n,) bool
        True for vertices that are a corner of a triangle hit by some pixel's ray.
    """
    hit = state.hits.prim_id
    tri = renderer.model.triangles[hit[hit >= 0]]
    visible = np.zeros(renderer.model.n_vertices, bool)
    visible[np.unique(tri)] = True
    return visible
