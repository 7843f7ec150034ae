"""Completing albedo maps: statistical inpainting with Poisson blending, eyeball specular.

Smith et al. 2020, "Inpainting": masked vertices (unobserved, or marked as
artefacts) of each sample are completed in two steps.

1. Statistical inpainting. A preliminary linear model is built with every
   masked value replaced by the mean of that vertex over the samples where it
   is not masked (where it is masked in every sample, the samples' own values
   are averaged). Each sample's model coefficients are fitted by least
   squares to its unmasked values only, and the model instance ``I_stat`` is
   the statistical guess for the masked part. The model of a sample is built
   from the other samples (see :func:`statistical_guess` for why).
2. Poisson blending. The completed map keeps the unmasked values exactly and
   solves, for the masked vertices, the least-squares problem

       G_t I = G_t I_stat   on triangles whose vertices are all masked,
       G_t I = 0            on triangles mixing masked and unmasked vertices,

   with ``G_t`` the per-triangle gradient
   (:func:`pipeline.texturing.poisson_stitching.gradient_operator`).
   The paper writes the unmasked rows as (unit-weight) equations; here they
   are eliminated as hard constraints, which is the limit of that weighting
   and keeps the observed data untouched. The zero-gradient rows on the
   boundary triangles make the fill continuous with its surroundings (no
   seam), the interior follows the statistical texture. A masked component
   not touching any unmasked vertex is held weakly (1e-6) to ``I_stat`` so
   that the system has full rank.

The process can be iterated (the completed maps rebuild the model).

Eyeball specular: the sparse LED dome rarely reflects off the highly specular
eyeball towards the camera, so the paper replaces specular albedo on the
eyeballs by a robust maximum: the 95th percentile of its estimated values in
that region (:func:`replace_eyeball_specular`).

Imports :mod:`albedo_model` and :mod:`pipeline.texturing.poisson_stitching`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from albedo_model.errors import InputError
from pipeline.texturing.poisson_stitching import gradient_operator

__all__ = [
    "poisson_blend",
    "replace_eyeball_specular",
    "statistical_guess",
    "statistical_inpaint",
]

_WEAK = 1e-6


def _check(maps: np.ndarray, masks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(maps, np.float64)
    m = np.asarray(masks, bool)
    if x.ndim != 3 or m.shape != x.shape[:2]:
        raise InputError(f"maps must be (S, n, C) and masks (S, n); got {x.shape} and {m.shape}")
    if not np.isfinite(x[~m]).all():
        raise InputError("unmasked map values must be finite")
    return x, m


def statistical_guess(maps: np.ndarray, masks: np.ndarray, *,
                      max_rows: int = 8000) -> np.ndarray:
    """``I_stat`` of every sample (step 1 of the module notes).

    Parameters
    ----------
    maps : (S, n, C) float array
        Per-vertex maps (masked values are ignored, except where a vertex is
        masked in every sample).
    masks : (S, n) bool array
        True where a value is to be filled.
    max_rows : int
        The coefficients of a sample are fitted to at most this many of its
        unmasked values (evenly strided; S - 1 unknowns need far fewer).

    Returns
    -------
    (S, n, C) float64

    Notes
    -----
    The preliminary model of sample ``i`` is built from the *other* samples
    (all their components). A model containing the sample itself reproduces it
    exactly from its unmasked values -- mean-filled holes included -- so the
    paper's fit would return the mean fill; leaving the sample out gives the
    statistical prediction the method intends. The model instance is
    ``mean_o + X_o^T a`` with ``X_o`` the others' centred data and ``a`` the
    least-squares fit on the unmasked values (minimum-norm where degenerate).
    """
    x, m = _check(maps, masks)
    s, n, c = x.shape
    if s < 3:
        return np.broadcast_to(np.where(m[..., None], 0.0, x).mean(axis=0), x.shape).copy()
    keep = (~m).astype(np.float64)
    count = keep.sum(axis=0)
    mean_obs = (np.where(m[..., None], 0.0, x)).sum(axis=0) / np.maximum(count, 1.0)[:, None]
    mean_all = np.nan_to_num(x).mean(axis=0)
    fill = np.where((count > 0)[:, None], mean_obs, mean_all)
    filled = np.where(m[..., None], fill[None], x).reshape(s, n * c)
    total = filled.sum(axis=0)
    out = np.empty_like(filled)
    for i in range(s):
        others = np.arange(s) != i
        mean_o = (total - filled[i]) / (s - 1)
        obs = np.flatnonzero(np.repeat(~m[i], c))
        if obs.size == 0:
            out[i] = mean_o
            continue
        rows = obs[:: max(1, obs.size // max_rows)]
        xo_rows = filled[np.ix_(others, rows)] - mean_o[rows]
        a, *_ = np.linalg.lstsq(xo_rows.T, filled[i, rows] - mean_o[rows], rcond=1e-10)
        # mean_o + a @ (others - mean_o), without copying the others
        coef = np.zeros(s)
        coef[others] = a
        out[i] = mean_o * (1.0 - a.sum()) + coef @ filled
    return out.reshape(s, n, c)


def poisson_blend(values: np.ndarray, guess: np.ndarray, mask: np.ndarray,
                  vertices: np.ndarray, triangles: np.ndarray, *,
                  gradient: sp.csr_matrix | None = None) -> np.ndarray:
    """Fill the masked vertices of one map (step 2 of the module notes).

    Parameters
    ----------
    values : (n, C) float array
        The map; masked entries are ignored.
    guess : (n, C) float array
        ``I_stat``, whose gradients the fill follows inside the masked region.
    mask : (n,) bool array
        True where values are filled.
    vertices : (n, 3) float array
    triangles : (m, 3) int array
    gradient : sparse (3m, n), optional
        :func:`pipeline.texturing.poisson_stitching.gradient_operator` of the mesh (pass it to
        share).

    Returns
    -------
    (n, C) float64
        Unmasked entries equal ``values``.
    """
    val = np.asarray(values, np.float64)
    gs = np.asarray(guess, np.float64)
    mk = np.asarray(mask, bool)
    tri = np.asarray(triangles, np.int64)
    out = val.copy()
    if not mk.any():
        return out
    masked_count = mk[tri].sum(axis=1)
    inner = masked_count == 3
    mixed = (masked_count > 0) & ~inner
    rows_t = np.flatnonzero(inner | mixed)
    G = (gradient_operator(vertices, tri) if gradient is None else gradient).tocsr()
    m_t = len(tri)
    rows = np.concatenate([rows_t + d * m_t for d in range(3)])
    g = G[rows]
    unknown = np.flatnonzero(mk)
    known = np.flatnonzero(~mk)
    a = g[:, unknown]
    target = np.where(np.tile(inner[rows_t], 3)[:, None], g @ gs, 0.0)
    rhs = target - g[:, known] @ val[known]
    lhs = (a.T @ a).tocsc()
    scale = max(float(lhs.diagonal().mean()), 1e-30)
    lhs = (lhs + sp.identity(len(unknown)) * (_WEAK * scale)).tocsc()
    rhs_n = a.T @ rhs + (_WEAK * scale) * gs[unknown]
    out[unknown] = splu(lhs, permc_spec="MMD_AT_PLUS_A").solve(rhs_n)
    return out


def statistical_inpaint(maps: np.ndarray, masks: np.ndarray, vertices: np.ndarray,
                        triangles: np.ndarray, *, iterations: int = 1) -> np.ndarray:
    """Statistical inpainting + Poisson blending of every sample's masked vertices.

    Parameters
    ----------
    maps : (S, n, C) float array
    masks : (S, n) bool array
        True where values are filled.
    vertices : (n, 3) float array
        Template mesh (gradients are taken on it).
    triangles : (m, 3) int array
    iterations : int
        Rebuild the model from the completed maps and repeat.

    Returns
    -------
    (S, n, C) float64
    """
    x, m = _check(maps, masks)
    if iterations < 1:
        raise InputError(f"iterations must be >= 1, got {iterations}")
    grad = gradient_operator(vertices, triangles).tocsr()
    current = x
    for it in range(iterations):
        guess = statistical_guess(current, m if it == 0 else np.zeros_like(m))
        current = np.stack([poisson_blend(x[i], guess[i], m[i], vertices, triangles,
                                          gradient=grad) for i in range(len(x))])
    return current


def replace_eyeball_specular(specular: np.ndarray, eyeballs: np.ndarray,
                             observed: np.ndarray | None = None, *,
                             percentile: float = 95.0) -> np.ndarray:
    """Set one map's eyeball specular albedo to a robust maximum of its values there.

    Parameters
    ----------
    specular : (n, C) float array
    eyeballs : (n,) bool array
    observed : (n,) bool array, optional
        Only these eyeball values enter the percentile (all when none is observed).
    percentile : float
        The paper's 95th percentile, per channel.

    Returns
    -------
    (n, C) float64
    """
    out = np.array(specular, np.float64)
    eye = np.asarray(eyeballs, bool)
    if not eye.any():
        return out
    use = eye if observed is None or not (eye & observed).any() else eye & observed
    out[eye] = np.percentile(out[use], percentile, axis=0)
    return out
