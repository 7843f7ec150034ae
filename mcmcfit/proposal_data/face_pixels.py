"""Face pixels of a render on the host: which pixels to use, and values interpolated at them.

The data-driven proposals read per-vertex quantities (albedo bases, normals,
albedo) at the face pixels of the accepted render: barycentric interpolation of
the ray-cast hits' triangle corners. Target pixels at or above
:data:`~proposals.albedo_solver.SATURATION_LIMIT` (linear) are left out: the
camera clipped them.

This module imports :mod:`albedo_model.errors` and :mod:`proposals.albedo_solver`
(the saturation limit), and :mod:`albedo_model.render.raycast` for type checking only.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from albedo_model.errors import InputError
from proposals.albedo_solver import SATURATION_LIMIT

if TYPE_CHECKING:
    from albedo_model.render.raycast import RayHits

__all__ = ["barycentric", "corner_weights", "render_state_of", "unsaturated"]


def unsaturated(target_linear: np.ndarray) -> np.ndarray:
    """Return (P,) bool: target pixels (P, 3) whose every channel is below the saturation limit."""
    return np.all(np.asarray(target_linear) < SATURATION_LIMIT, axis=1)


def corner_weights(hits: RayHits, pixels: np.ndarray, dtype=np.float32) -> np.ndarray:
    """Return the barycentric weights (N, 3) of the hit triangle's corners at ``pixels``.

    Parameters
    ----------
    hits : RayHits
        Whole-image ray-cast buffers (row-major).
    pixels : (N,) int array
        Row-major pixel indices whose rays hit.
    dtype : numpy dtype
        Of the weights (the buffers are float32).

    Returns
    -------
    (N, 3) array ``(1 - u - v, u, v)`` for the corners ``triangles[prim_id]``.
    """
    u = hits.bary[pixels, 0].astype(dtype)
    v = hits.bary[pixels, 1].astype(dtype)
    return np.stack([1.0 - u - v, u, v], axis=1)


def barycentric(weights: np.ndarray, corners: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Interpolate per-vertex ``values`` (n, ...) at N points inside triangles.

    ``out[i] = sum_k weights[i, k] values[corners[i, k]]``.

    Parameters
    ----------
    weights : (N, 3) float array
        Barycentric weights (:func:`corner_weights`).
    corners : (N, 3) int array
        The vertices of the triangle each point lies in.
    values : (n, ...) array
        Per-vertex values, e.g. (n, 3) colours or (n, 3, K) bases.

    Returns
    -------
    (N, ...) array in the dtype of ``weights`` and ``values``.
    """
    return np.einsum("nk,nk...->n...", weights, values[corners])


def render_state_of(state, what: str):
    """Return the accepted render state a proposal was handed, or raise a clear error.

    Parameters
    ----------
    state : ProposalState or ChainState
        What the sampler passes a proposal.
    what : str
        Names the data in the error.

    Raises
    ------
    InputError
        The state carries no render (a data-driven proposal in the landmark stage),
        or a render of other parameters.
    """
    rs = state.render_state
    if rs is None:
        raise InputError(f"{what} need the render of the accepted state: use them in the image "
                         "stage only")
    if rs.params is not state.params:
        raise InputError(f"{what}: the render handed with the state is of other parameters")
    return rs
