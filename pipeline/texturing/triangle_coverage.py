"""Which pixel centres a set of projected triangles covers (a vectorised coverage rasteriser).

Used for the silhouette of a mesh in a view: the union of its projected
triangles, with no depth test (occlusion does not change the union).
Triangles are grouped by the size of their pixel bounding box (powers of two)
and each group tests a fixed square of candidate pixels per triangle, so the
work is vectorised over triangles; huge triangles are processed in chunks that
bound the memory.

Imports only :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.errors import InputError

__all__ = ["coverage_mask"]

_MAX_CANDIDATES = 1 << 21  # candidate pixels tested at once (bounds memory to ~100 MB)


def coverage_mask(triangles_px: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Pixels whose centre lies in at least one triangle (edges included).

    Parameters
    ----------
    triangles_px : (m, 3, 2) float array
        Triangle corners as ``(u, v)`` 0-based pixel coordinates (column, row;
        pixel ``(r, c)`` is centred at ``(c, r)``). Triangles with a non-finite
        corner or zero area are skipped; either winding is accepted.
    shape : (H, W)

    Returns
    -------
    (H, W) bool
    """
    tri = np.asarray(triangles_px, np.float64)
    if tri.ndim != 3 or tri.shape[1:] != (3, 2):
        raise InputError(f"triangles_px must have shape (m, 3, 2), got {tri.shape}")
    h, w = (int(s) for s in shape)
    mask = np.zeros((h, w), bool)
    if h < 1 or w < 1 or len(tri) == 0:
        return mask
    x, y = np.ascontiguousarray(tri[:, :, 0]), np.ascontiguousarray(tri[:, :, 1])
    # edge i runs from corner i to corner i+1: e_i(p) = a_i (p_x - x_i) + b_i (p_y - y_i)
    a = y - np.roll(y, -1, axis=1)
    b = np.roll(x, -1, axis=1) - x
    area2 = b[:, 0] * (y[:, 2] - y[:, 0]) + a[:, 0] * (x[:, 2] - x[:, 0])
    x_lo = np.minimum(np.minimum(x[:, 0], x[:, 1]), x[:, 2])
    x_hi = np.maximum(np.maximum(x[:, 0], x[:, 1]), x[:, 2])
    y_lo = np.minimum(np.minimum(y[:, 0], y[:, 1]), y[:, 2])
    y_hi = np.maximum(np.maximum(y[:, 0], y[:, 1]), y[:, 2])
    c0, c1 = np.maximum(np.ceil(x_lo), 0), np.minimum(np.floor(x_hi), w - 1)
    r0, r1 = np.maximum(np.ceil(y_lo), 0), np.minimum(np.floor(y_hi), h - 1)
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(area2) & (area2 != 0) & (c1 >= c0) & (r1 >= r0)
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        return mask
    sign = np.sign(area2[idx])[:, None]  # counter-clockwise in (u, v): inside means all e_i >= 0
    a, b = a[idx] * sign, b[idx] * sign
    c0, r0 = c0[idx], r0[idx]
    e0 = a * (c0[:, None] - x[idx]) + b * (r0[:, None] - y[idx])  # edge values at (c0, r0)
    wc = (c1[idx] - c0).astype(np.int64)
    wr = (r1[idx] - r0).astype(np.int64)
    c0, r0 = c0.astype(np.int64), r0.astype(np.int64)
    level = np.ceil(np.log2(np.maximum(wc, wr) + 1)).astype(np.int64)
    for lev in np.unique(level):
        k = 1 << int(lev)
        group = np.flatnonzero(level == lev)
        step = max(1, _MAX_CANDIDATES // (k * k))
        for start in range(0, len(group), step):
            g = group[start:start + step]
            _fill(mask, e0[g], a[g], b[g], c0[g], r0[g], wc[g], wr[g], k)
    return mask


def _fill(mask, e0, a, b, c0, r0, wc, wr, k) -> None:
    """Mark the covered centres of triangles whose boxes (wc+1 x wr+1) fit in k x k pixels."""
    off = np.arange(k, dtype=np.float64)
    inside = (off[None, None, :] <= wc[:, None, None]) & (off[None, :, None] <= wr[:, None, None])
    for i in range(3):
        inside &= (e0[:, i, None, None] + a[:, i, None, None] * off[None, None, :]
                   + b[:, i, None, None] * off[None, :, None]) >= 0
    t, dr, dc = np.nonzero(inside)
    mask[r0[t] + dr, c0[t] + dc] = True
