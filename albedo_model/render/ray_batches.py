"""NumPy side of the ray caster: ray buffers, hit records, pixel-grid windows and leak closing.

:class:`albedo_model.render.raycast.RayCaster` queries Embree; everything around
those queries that is plain array work lives here, so that it can be read (and
tested) without a scene: checking and converting ray and vertex buffers, the
bounds of the vertices and the model-unit scale derived from them, the
:class:`RayHits` record, casting only a window of a pixel grid, re-casting the
isolated misses of a grid (edge leaks of the non-robust traversal), continuing
rays past back-facing hits, and the three slightly tilted rays of a point
visibility test.

Functions that need new hits take the query as a callable (``cast`` or
``intersect``), so they never see a scene.

This module imports only :mod:`albedo_model.errors`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError

__all__ = [
    "MAX_CONTINUE",
    "RayHits",
    "as_rays",
    "bounds_scale",
    "cast_window",
    "checked_mesh",
    "checked_vertices",
    "close_leaks",
    "continue_past_backfaces",
    "grid_window",
    "ray_pair",
    "vertex_bounds",
    "visibility_rays",
]

MAX_CONTINUE = 8  # back-face continuation rounds before a ray is declared a miss


class RayHits(NamedTuple):
    """Nearest front-facing hits of a batch of rays.

    Attributes
    ----------
    prim_id : (P,) int32
        Triangle index, -1 for a miss.
    bary : (P, 2) float32
        Embree's (u, v): the hit point is ``(1-u-v) a + u b + v c`` for triangle
        ``(a, b, c)``; 0 for misses. In the model frame these are also the
        perspective-correct barycentrics of the pixel.
    t : (P,) float32
        Ray parameter of the hit (in units of the direction's length); inf for misses.
    """

    prim_id: np.ndarray
    bary: np.ndarray
    t: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        """(P,) bool, True where a triangle was hit."""
        return self.prim_id >= 0


def as_rays(a: np.ndarray, name: str) -> np.ndarray:
    """Convert ``a`` to a contiguous (P, 3) float32 ray buffer.

    Parameters
    ----------
    a : array_like
        Ray origins or directions.
    name : str
        Argument name for the error message.

    Returns
    -------
    (P, 3) float32 array

    Raises
    ------
    InputError
        When ``a`` is not of shape (P, 3).
    """
    a = np.ascontiguousarray(a, dtype=np.float32)
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"{name} must have shape (P, 3), got {a.shape}")
    return a


def ray_pair(origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Convert origins and directions with :func:`as_rays` and check that they pair up.

    Parameters
    ----------
    origins : (P, 3) array_like
    directions : (P, 3) or (1, 3) array_like

    Returns
    -------
    (origins, directions) : float32 arrays
    """
    o = as_rays(origins, "origins")
    d = as_rays(directions, "directions")
    if len(d) not in (1, len(o)):
        raise InputError(f"directions must have shape (1, 3) or {o.shape}, got {d.shape}")
    return o, d


def checked_vertices(vertices: np.ndarray, n: int | None = None) -> np.ndarray:
    """Convert vertices to a contiguous finite (n, 3) float32 array.

    Parameters
    ----------
    vertices : (n, 3) array_like
    n : int, optional
        Required number of vertices (an update keeps the topology).

    Returns
    -------
    (n, 3) float32 array
    """
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    if v.ndim != 2 or v.shape[1] != 3 or (n is not None and len(v) != n):
        want = "(n, 3)" if n is None else f"({n}, 3)"
        raise InputError(f"vertices must have shape {want}, got {v.shape}")
    if not np.isfinite(v).all():
        raise InputError("vertices contain NaN or inf")
    return v


def checked_mesh(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Check a triangle mesh and convert it to the buffers Embree reads.

    Parameters
    ----------
    vertices : (n, 3) array_like
    triangles : (m, 3) integer array_like, indices into ``vertices``

    Returns
    -------
    (vertices, triangles) : (n, 3) float32 and (m, 3) int32 contiguous arrays
    """
    tri = np.asarray(triangles)
    if tri.ndim != 2 or tri.shape[1] != 3 or not np.issubdtype(tri.dtype, np.integer):
        raise InputError(
            f"triangles must be an (m, 3) integer array, got {tri.shape} {tri.dtype}")
    v = checked_vertices(vertices)
    if tri.size and (tri.min() < 0 or tri.max() >= len(v)):
        raise InputError(f"triangle indices must lie in [0, {len(v)})")
    return v, np.ascontiguousarray(tri, dtype=np.int32)


def vertex_bounds(v: np.ndarray) -> np.ndarray:
    """Compute the (2, 3) min and max corner of (n, 3) points (read-only float64).

    Parameters
    ----------
    v : (n, 3) array

    Returns
    -------
    (2, 3) float64 array, zeros for no points
    """
    b = np.zeros((2, 3))
    if len(v):
        # per column: an axis-0 reduction of an (n, 3) array is 10x slower
        for c in range(3):
            col = v[:, c]
            b[0, c], b[1, c] = col.min(), col.max()
    b.flags.writeable = False
    return b


def bounds_scale(bounds: np.ndarray) -> float:
    """Return the diagonal of a bounding box, the model-unit scale of ray offsets (1 if empty).

    Parameters
    ----------
    bounds : (2, 3) array, as from :func:`vertex_bounds`

    Returns
    -------
    float
    """
    return float(np.linalg.norm(bounds[1] - bounds[0])) or 1.0


def grid_window(n_rays: int, image_shape: tuple[int, int] | None,
                window: tuple[int, int, int, int] | None) -> tuple[int, int, int, int] | None:
    """Check a pixel grid and its window; return the window to cast, None for the whole grid.

    A window wider than 3/4 of the image is widened to whole rows (see
    :func:`cast_window`).

    Parameters
    ----------
    n_rays : int
        Number of rays (must equal H * W when ``image_shape`` is given).
    image_shape : (H, W), optional
    window : (y0, y1, x0, x1), optional
        Needs ``image_shape``; must lie inside the image.

    Returns
    -------
    (y0, y1, x0, x1) or None
    """
    if image_shape is not None and int(image_shape[0]) * int(image_shape[1]) != n_rays:
        raise InputError(f"image_shape {tuple(image_shape)} does not match {n_rays} rays")
    if window is None:
        return None
    if image_shape is None:
        raise InputError("a window needs image_shape")
    h, w = (int(x) for x in image_shape)
    y0, y1, x0, x1 = (int(x) for x in window)
    if not (0 <= y0 <= y1 <= h and 0 <= x0 <= x1 <= w):
        raise InputError(f"window {tuple(window)} is not inside the image {h}x{w}")
    if x1 - x0 > 0.75 * w:  # see cast_window
        x0, x1 = 0, w
    if (y0, y1, x0, x1) != (0, h, 0, w):
        return y0, y1, x0, x1
    return None


def cast_window(cast: Callable[..., RayHits], o: np.ndarray, d: np.ndarray,
                image_shape: tuple[int, int], window: tuple[int, int, int, int]) -> RayHits:
    """Cast the window's rays of an (h, w) grid; report misses elsewhere.

    Whole rows are contiguous slices of the ray arrays (no copy);
    :func:`grid_window` widens a window to whole rows unless that adds a third
    (copying the rays and hits costs about as much as casting a few percent of them).

    Parameters
    ----------
    cast : callable
        ``cast(origins, directions, image_shape) -> RayHits`` on a sub-grid.
    o : (h * w, 3) float32
    d : (h * w, 3) or (1, 3) float32
    image_shape : (h, w)
    window : (y0, y1, x0, x1), as from :func:`grid_window`

    Returns
    -------
    RayHits
        Of all h * w rays.
    """
    h, w = (int(x) for x in image_shape)
    y0, y1, x0, x1 = window
    prim = np.full(h * w, -1, np.int32)
    bary = np.zeros((h * w, 2), np.float32)
    t = np.full(h * w, np.inf, np.float32)
    if y1 <= y0 or x1 <= x0:
        return RayHits(prim, bary, t)
    rows = slice(y0 * w, y1 * w)
    if (x0, x1) == (0, w):
        r = cast(o[rows], d if len(d) == 1 else d[rows], (y1 - y0, w))
        prim[rows], bary[rows], t[rows] = r.prim_id, r.bary, r.t
        return RayHits(prim, bary, t)

    def sub(a):
        return np.ascontiguousarray(a.reshape(h, w, 3)[y0:y1, x0:x1]).reshape(-1, 3)

    shape = (y1 - y0, x1 - x0)
    r = cast(sub(o), d if len(d) == 1 else sub(d), shape)
    prim.reshape(h, w)[y0:y1, x0:x1] = r.prim_id.reshape(shape)
    bary.reshape(h, w, 2)[y0:y1, x0:x1] = r.bary.reshape(*shape, 2)
    t.reshape(h, w)[y0:y1, x0:x1] = r.t.reshape(shape)
    return RayHits(prim, bary, t)


def continue_past_backfaces(intersect: Callable, o: np.ndarray, d: np.ndarray,
                            limit: float | None, prim: np.ndarray, bary: np.ndarray,
                            t: np.ndarray, idx: np.ndarray, scale: float,
                            rounds: int = MAX_CONTINUE) -> None:
    """Re-cast rays ``idx`` from just behind their back-facing hits (in place).

    Parameters
    ----------
    intersect : callable
        ``intersect(origins, directions, tfar) -> (prim, bary, t, back)``: the
        nearest hits of either side and whether each is back-facing.
    o, d : float32 ray buffers of all rays
    limit : float, optional
        Largest ray parameter of the original rays.
    prim, bary, t : hit arrays of all rays, updated in place
    idx : int array
        Rays whose nearest hit is back-facing.
    scale : float
        Model-unit scale (:func:`bounds_scale`); the restart lies ``1e-5 * scale`` behind the hit.
    rounds : int
        Continuation rounds before a ray still hitting back faces is declared a miss.
    """
    for _ in range(rounds):
        dd = d[idx] if len(d) > 1 else np.broadcast_to(d, (len(idx), 3))
        dn = np.linalg.norm(dd.astype(np.float64), axis=1)
        start = t[idx].astype(np.float64) + 1e-5 * scale / np.maximum(dn, 1e-30)
        oo = (o[idx] + start[:, None] * dd).astype(np.float32)
        rest = None if limit is None else np.maximum(limit - start, 0.0).astype(np.float32)
        p2, b2, t2, back = intersect(oo, np.ascontiguousarray(dd, np.float32), rest)
        hit = p2 >= 0
        prim[idx] = p2
        bary[idx] = b2
        t[idx] = np.where(hit, t2 + start, np.inf)
        back &= hit
        idx = idx[back]
        if idx.size == 0:
            return
    prim[idx] = -1
    bary[idx] = 0.0
    t[idx] = np.inf


def close_leaks(cast: Callable[..., RayHits], o: np.ndarray, d: np.ndarray, prim: np.ndarray,
                bary: np.ndarray, t: np.ndarray, image_shape: tuple[int, int]) -> None:
    """Re-cast isolated misses of a pixel grid with slightly shifted rays (in place).

    Every miss between two hits (horizontally or vertically) is re-cast 1/1000
    pixel towards its right neighbour, and if it still misses towards the one
    below (left / above on the last column / row).

    Parameters
    ----------
    cast : callable
        ``cast(origins, directions) -> RayHits``.
    o, d : float32 ray buffers of the (H * W) grid
    prim, bary, t : hit arrays of the grid, updated in place
    image_shape : (H, W)
    """
    h, w = (int(x) for x in image_shape)
    hit = (prim >= 0).reshape(h, w)
    cand = np.zeros((h, w), bool)
    cand[:, 1:-1] = hit[:, :-2] & hit[:, 2:]
    cand[1:-1, :] |= hit[:-2, :] & hit[2:, :]
    cand &= ~hit
    idx = np.flatnonzero(cand)
    for step in (1, w):
        if idx.size == 0:
            return
        last = idx % w == w - 1 if step == 1 else idx // w == h - 1
        nb = np.where(last, idx - step, idx + step)
        oo = o[idx] + 1e-3 * (o[nb] - o[idx])
        dd = d if len(d) == 1 else d[idx] + 1e-3 * (d[nb] - d[idx])
        r = cast(oo, dd)
        got = r.prim_id >= 0
        prim[idx[got]], bary[idx[got]], t[idx[got]] = r.prim_id[got], r.bary[got], r.t[got]
        idx = idx[~got]


def visibility_rays(points_model: np.ndarray, eye_model: np.ndarray | None, eps: float,
                    direction: np.ndarray | None = None):
    """Build the occlusion rays of a point visibility test: three per point.

    Parameters
    ----------
    points_model : (n, 3) array_like, model frame
    eye_model : (3,) array_like or None
        Camera centre in the model frame; None for an orthographic camera.
    eps : float
        Offset of the ray start towards the camera, in model units.
    direction : (3,) array_like, optional
        With ``eye_model=None``: the model-frame direction towards the camera.

    Returns
    -------
    origins : (3 n, 3) float32
    directions : (3 n, 3) float32
        The direct rays, then the two copies tilted by 1e-5 rad.
    tmax : (3 n,) float32 or None
        Segment ends (just short of the eye); None for orthographic cameras.
    """
    p = np.asarray(points_model, np.float64).reshape(-1, 3)
    if eye_model is not None:
        to_eye = np.asarray(eye_model, np.float64).reshape(1, 3) - p
        dist = np.linalg.norm(to_eye, axis=1)
        u = to_eye / np.maximum(dist, 1e-30)[:, None]
        tmax = np.maximum(dist - 2.0 * eps, 0.0).astype(np.float32)
    elif direction is not None:
        u = np.broadcast_to(np.asarray(direction, np.float64) / np.linalg.norm(direction), p.shape)
        tmax = None
    else:
        raise InputError("visible_points needs eye_model or direction")
    # Two slightly tilted copies of each ray: a leak through an edge (non-robust
    # traversal, e.g. a midline point seen in the symmetry plane) must not make
    # an occluded point visible. The tilt (1e-5 rad) moves nothing near the point.
    side1 = np.cross(u, np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    side1 /= np.linalg.norm(side1, axis=1, keepdims=True)
    side2 = np.cross(u, side1)
    start = (p + eps * u).astype(np.float32)
    origins = np.concatenate([start, start, start])
    dirs = np.concatenate([u, u + 1e-5 * side1, u + 1e-5 * side2]).astype(np.float32)
    return origins, dirs, None if tmax is None else np.tile(tmax, 3)
