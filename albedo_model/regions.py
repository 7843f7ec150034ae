"""Face regions of a morphable model, cut from its Basel-named landmarks on the mean shape.

Every rule reads landmark positions only (the model's landmarks that resolve to
a vertex, :attr:`~albedo_model.model.MorphableModel.landmark_vertices`, taken on
the mean shape), so it works in any model frame and unit:

**Face frame.** ``lateral`` is the mean of ``left.X - right.X`` over every
landmark present on both sides (towards the subject's left); ``up`` runs from the
mean of the lip and chin landmarks to the mean of the eye, eyebrow and trichion
landmarks, made orthogonal to ``lateral``; ``forward`` = ``lateral x up``, its
sign chosen so that the nose tip (else the landmarks' mean) lies in front of the
vertices' centroid. Vertex coordinates ``(X, Y, Z)`` are taken along these axes.

**Regions** (each needs the landmarks named; without them it is omitted, never
guessed). Lengths scale with the landmarks they are cut from:

``eyes``
    Per side with both ``eye.corner_inner`` and ``eye.corner_outer``: the ellipse
    in (X, Y) centred between the corners, semi-axes 1.15 x half the corner
    distance and 1.15 x half the ``eye.top`` - ``eye.bottom`` height (0.4 x the
    first without those two), within that semi-axis in depth of the corners.
``lips``
    Both ``lips.corner``, ``center.lips.upper.outer``, ``center.lips.lower.outer``:
    between the parabolas through the corners and the upper (lower) outer lip
    point, widened by 8 % of the lip height, in front of the corners' depth less
    half the mouth width.
``nose``
    ``center.nose.tip``, both ``nose.wing.outer`` and both ``eye.corner_inner``:
    from the subnasale (``center.nose.attachement_to_philtrum``, else the lowest
    of the wing and nostril landmarks) up to the inner eye corners; half width
    1.1 x the wing half width up to the wings, narrowing linearly to 0.4 x half
    the inner-corner distance at the top; in front of the depth interpolated
    the same way between the wings and the inner eye corners.
``chin``
    ``center.chin.tip``, ``center.lips.lower.outer`` and both ``lips.corner``:
    the ellipse of half width half the mouth width spanning from 10 % of the
    lip-chin height L below the chin tip to L / 4 below the lower lip, in front of
    the chin tip's depth less L / 2.
``left_cheek``, ``right_cheek``
    The side's ``eye.corner_outer``, ``lips.corner`` and ``nose.wing.outer``:
    between 1.2 x the wing's and 1.1 x the outer eye corner's lateral distance
    from the face's midline, from the lip corner up to 20 % of the eye width E
    below the eye (``eye.bottom``, else the outer corner), in front of the outer
    corner's depth less E / 2.
``forehead``
    ``center.front.trichion``, both ``eyebrow.bend.upper`` (or
    ``eyebrow.inner_upper``) and both ``eye.corner_outer``: from 15 % of the
    brow-trichion height H above the highest brow landmark up to the trichion,
    within the outer eye corners, in front of the brows' depth less H / 2.

Regions are made disjoint by precedence in the order above (a vertex belongs to
the first region that claims it).

This module imports :mod:`albedo_model.model`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.model import MorphableModel

__all__ = ["REGION_NAMES", "face_frame", "face_regions", "region_masks"]

#: Every region a model can have, in precedence order.
REGION_NAMES = ("eyes", "lips", "nose", "chin", "left_cheek", "right_cheek", "forehead")

_UPPER = (".eye.", ".eyebrow.", "trichion")
_LOWER = (".lips.", ".chin.")


def face_frame(points: dict[str, np.ndarray], vertices: np.ndarray) -> np.ndarray | None:
    """Rows ``lateral`` (to the subject's left), ``up`` and ``forward`` of the face frame.

    Parameters
    ----------
    points : mapping name -> (3,) float, model frame
        Landmark positions (Basel names).
    vertices : (n, 3) float, model frame
        The mesh (its centroid orients ``forward`` when there is no nose tip).

    Returns
    -------
    (3, 3) float64 orthonormal rows, or None when no left/right pair or no upper
    and lower landmarks define it.
    """
    pairs = [points[n] - points["right." + n[5:]] for n in points
             if n.startswith("left.") and "right." + n[5:] in points]
    upper = [p for n, p in points.items() if any(k in n for k in _UPPER)]
    lower = [p for n, p in points.items() if any(k in n for k in _LOWER)]
    if not pairs or not upper or not lower:
        return None
    lateral = np.mean(pairs, axis=0)
    up = np.mean(upper, axis=0) - np.mean(lower, axis=0)
    if np.linalg.norm(lateral) == 0.0:
        return None
    lateral = lateral / np.linalg.norm(lateral)
    up = up - (up @ lateral) * lateral
    if np.linalg.norm(up) == 0.0:
        return None
    up = up / np.linalg.norm(up)
    forward = np.cross(lateral, up)
    front = points.get("center.nose.tip", np.mean(list(points.values()), axis=0))
    if (front - np.asarray(vertices, np.float64).mean(axis=0)) @ forward < 0.0:
        forward = -forward
    return np.stack([lateral, up, forward])


def _eyes(c, v) -> np.ndarray | None:
    mask = np.zeros(v.shape[0], bool)
    found = False
    for side in ("left", "right"):
        inner, outer = c.get(f"{side}.eye.corner_inner"), c.get(f"{side}.eye.corner_outer")
        if inner is None or outer is None:
            continue
        found = True
        centre = (inner + outer) / 2.0
        a = 1.15 * abs(outer[0] - inner[0]) / 2.0
        top, bottom = c.get(f"{side}.eye.top"), c.get(f"{side}.eye.bottom")
        b = 1.15 * abs(top[1] - bottom[1]) / 2.0 if top is not None and bottom is not None \
            else 0.4 * a
        mask |= ((((v[:, 0] - centre[0]) / a) ** 2 + ((v[:, 1] - centre[1]) / b) ** 2 <= 1.0)
                 & (np.abs(v[:, 2] - centre[2]) < a))
    return mask if found else None


def _lips(c, v) -> np.ndarray | None:
    need = ("left.lips.corner", "right.lips.corner", "center.lips.upper.outer",
            "center.lips.lower.outer")
    if any(n not in c for n in need):
        return None
    left, right, up, low = (c[n] for n in need)
    half = abs(left[0] - right[0]) / 2.0
    cx, cy, cz = (left + right) / 2.0
    t = (v[:, 0] - cx) / half
    bump = np.clip(1.0 - t ** 2, 0.0, None)
    margin = 0.08 * (up[1] - low[1])
    return ((np.abs(t) <= 1.0) & (v[:, 1] <= cy + (up[1] - cy) * bump + margin)
            & (v[:, 1] >= cy + (low[1] - cy) * bump - margin) & (v[:, 2] > cz - half / 2.0))


def _nose(c, v) -> np.ndarray | None:
    need = ("center.nose.tip", "left.nose.wing.outer", "right.nose.wing.outer",
            "left.eye.corner_inner", "right.eye.corner_inner")
    if any(n not in c for n in need):
        return None
    _, wl, wr, el, er = (c[n] for n in need)
    if "center.nose.attachement_to_philtrum" in c:
        y_low = c["center.nose.attachement_to_philtrum"][1]
    else:
        y_low = min(p[1] for n, p in c.items() if ".nose.wing." in n or ".nose.hole." in n)
    wing, eyes = (wl + wr) / 2.0, (el + er) / 2.0
    # s = 0 at the wings (and below), 1 at the inner eye corners
    s = np.clip((v[:, 1] - wing[1]) / (eyes[1] - wing[1]), 0.0, 1.0)
    half = (1.0 - s) * 1.1 * abs(wl[0] - wr[0]) / 2.0 + s * 0.4 * abs(el[0] - er[0]) / 2.0
    depth = (1.0 - s) * wing[2] + s * eyes[2]
    return ((v[:, 1] >= y_low) & (v[:, 1] <= eyes[1]) & (np.abs(v[:, 0] - wing[0]) <= half)
            & (v[:, 2] >= depth))


def _chin(c, v) -> np.ndarray | None:
    need = ("center.chin.tip", "center.lips.lower.outer", "left.lips.corner", "right.lips.corner")
    if any(n not in c for n in need):
        return None
    tip, low, left, right = (c[n] for n in need)
    height = low[1] - tip[1]
    top, bottom = low[1] - height / 4.0, tip[1] - 0.1 * height
    cx, half = (left[0] + right[0]) / 2.0, abs(left[0] - right[0]) / 2.0
    cy, hy = (top + bottom) / 2.0, (top - bottom) / 2.0
    return ((((v[:, 0] - cx) / half) ** 2 + ((v[:, 1] - cy) / hy) ** 2 <= 1.0)
            & (v[:, 2] > tip[2] - height / 2.0))


def _cheek(c, v, side: str) -> np.ndarray | None:
    need = (f"{side}.eye.corner_outer", f"{side}.lips.corner", f"{side}.nose.wing.outer")
    if any(n not in c for n in need):
        return None
    eye, lip, wing = (c[n] for n in need)
    mid = [p[0] for n, p in c.items() if n.startswith("center.")]
    x0 = float(np.mean(mid)) if mid else 0.0
    sign = 1.0 if side == "left" else -1.0
    d = sign * (v[:, 0] - x0)
    inner = c.get(f"{side}.eye.corner_inner")
    width = abs(eye[0] - inner[0]) if inner is not None else abs(eye[0] - x0) / 2.0
    y_eye = c[f"{side}.eye.bottom"][1] if f"{side}.eye.bottom" in c else eye[1]
    return ((d >= 1.2 * abs(wing[0] - x0)) & (d <= 1.1 * abs(eye[0] - x0))
            & (v[:, 1] >= lip[1]) & (v[:, 1] <= y_eye - 0.2 * width)
            & (v[:, 2] > eye[2] - width / 2.0))


def _forehead(c, v) -> np.ndarray | None:
    brows = [c[f"{s}.eyebrow.{k}"] for s in ("left", "right") for k in ("bend.upper", "inner_upper")
             if f"{s}.eyebrow.{k}" in c]
    sides = {s for s in ("left", "right")
             if any(f"{s}.eyebrow.{k}" in c for k in ("bend.upper", "inner_upper"))}
    need = ("center.front.trichion", "left.eye.corner_outer", "right.eye.corner_outer")
    if sides != {"left", "right"} or any(n not in c for n in need):
        return None
    tri, el, er = (c[n] for n in need)
    y_brow = max(p[1] for p in brows)
    height = tri[1] - y_brow
    z_brow = float(np.mean([p[2] for p in brows]))
    cx, half = (el[0] + er[0]) / 2.0, abs(el[0] - er[0]) / 2.0
    return ((v[:, 1] >= y_brow + 0.15 * height) & (v[:, 1] <= tri[1])
            & (np.abs(v[:, 0] - cx) <= half) & (v[:, 2] > z_brow - height / 2.0))


def region_masks(vertices: np.ndarray, points: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Disjoint boolean region masks from landmark positions (rules in the module notes).

    Parameters
    ----------
    vertices : (n, 3) float, model frame
        The mesh the masks are cut on (the mean shape).
    points : mapping name -> (3,) float, model frame
        Landmark positions, Basel names.

    Returns
    -------
    dict name -> (n,) bool
        The regions that can be defined, in :data:`REGION_NAMES` order; a region
        whose rule selects no vertex is left out. Empty when the face frame
        cannot be built.
    """
    v = np.asarray(vertices, np.float64)
    pts = {str(k): np.asarray(p, np.float64) for k, p in points.items()}
    frame = face_frame(pts, v)
    if frame is None:
        return {}
    vf = v @ frame.T
    c = {k: p @ frame.T for k, p in pts.items()}
    rules = {"eyes": _eyes, "lips": _lips, "nose": _nose, "chin": _chin,
             "left_cheek": lambda c, v: _cheek(c, v, "left"),
             "right_cheek": lambda c, v: _cheek(c, v, "right"), "forehead": _forehead}
    taken = np.zeros(v.shape[0], bool)
    out = {}
    for name in REGION_NAMES:
        mask = rules[name](c, vf)
        if mask is None:
            continue
        mask = mask & ~taken
        if mask.any():
            out[name] = mask
            taken |= mask
    return out


def face_regions(model: MorphableModel) -> dict[str, np.ndarray]:
    """Region masks of ``model`` on its mean shape (see :func:`region_masks`).

    Parameters
    ----------
    model : MorphableModel
        Its landmarks that resolve to a vertex
        (:attr:`~albedo_model.model.MorphableModel.landmark_vertices`) are read on
        the mean shape (with the mean expression).

    Returns
    -------
    dict name -> (n_vertices,) bool
    """
    mean = model.shape_instance()
    points = {name: mean[i] for name, i in model.landmark_vertices.items()}
    return region_masks(mean, points)
