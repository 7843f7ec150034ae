"""Bilateral symmetry of per-vertex fields: mirroring across the plane x = 0.

This module imports only numpy.
"""

from __future__ import annotations

import numpy as np

__all__ = ["mirror_flat"]


def mirror_flat(flat: np.ndarray, symmetry: np.ndarray) -> np.ndarray:
    """Mirror an interleaved field or shape across x = 0.

    Parameters
    ----------
    flat : (3n,) or (3n, k) array
        Interleaved ``x0 y0 z0 x1 ...`` (per column).
    symmetry : (n,) int array

    Returns
    -------
    Same shape: ``out[i] = S flat[symmetry[i]]`` per vertex with ``S = diag(-1, 1, 1)``.
    """
    a = np.asarray(flat)
    n = len(symmetry)
    v = a.reshape(n, 3, -1)[symmetry].copy()
    v[:, 0] *= -1.0
    return v.reshape(a.shape)
