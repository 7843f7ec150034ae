"""Posterior summaries of per-vertex albedo from coefficient samples.

An albedo PCA part is linear in its coefficients, so the posterior mean and
standard deviation of every vertex colour follow exactly from the mean and
covariance of the coefficient samples (no per-sample instances needed); the
credible interval bounds need the samples and are computed in vertex blocks to
bound memory.

This module imports only :mod:`albedo_model.errors` and :mod:`albedo_model.pca`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.pca import PCAPart

__all__ = ["AlbedoPosterior", "albedo_posterior", "visible_vertices"]


class AlbedoPosterior(NamedTuple):
    """Per-vertex posterior of one albedo part, each (n, 3) float32 linear sRGB.

    Attributes
    ----------
    mean, std : posterior mean and standard deviation
    lo, hi : lower and upper bounds of the central credible interval
    level : the interval's probability (e.g. 0.9 for 5 % / 95 %)
    """

    mean: np.ndarray
    std: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    level: float


def albedo_posterior(part: PCAPart, coefficients: np.ndarray, *, level: float = 0.9,
                     block_rows: int = 8192) -> AlbedoPosterior:
    """Posterior mean, std and central interval of ``part``'s instance.

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

    Returns
    -------
    AlbedoPosterior

    Notes
    -----
    With ``x = mu + W c`` (``W = U diag(sqrt(lambda))``): ``E[x] = mu + W E[c]`` and
    ``Var[x_i] = W_i Cov[c] W_i^T``, evaluated as ``sum((W C) * W, axis=1)``.
    """
    c = np.asarray(coefficients, np.float64)
    if c.ndim != 2 or c.shape[0] < 1:
        raise InputError(f"coefficient samples must be (S, j) with S >= 1, got shape {c.shape}")
    if c.shape[1] > part.rank:
        raise InputError(f"{c.shape[1]} coefficients for a rank-{part.rank} part")
    if not 0 < level < 1:
        raise InputError(f"level must be in (0, 1), got {level}")
    j = c.shape[1]
    w = part.scaled_basis[:, :j].astype(np.float64)
    mean = part.mean.astype(np.float64) + w @ c.mean(0)
    cov = np.cov(c, rowvar=False, ddof=0).reshape(j, j) if c.shape[0] > 1 else np.zeros((j, j))
    var = np.einsum("ij,ij->i", w @ cov, w)
    std = np.sqrt(np.maximum(var, 0.0))
    q = [(1 - level) / 2, 1 - (1 - level) / 2]
    lo = np.empty(part.dim)
    hi = np.empty(part.dim)
    base = part.mean.astype(np.float64)
    for start in range(0, part.dim, block_rows):
        sl = slice(start, start + block_rows)
        x = base[sl] + c @ w[sl].T  # (S, rows)
        lo[sl], hi[sl] = np.quantile(x, q, axis=0)
    shape = (-1, 3)
    f32 = lambda a: a.reshape(shape).astype(np.float32)  # noqa: E731
    return AlbedoPosterior(f32(mean), f32(std), f32(lo), f32(hi), float(level))


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
