"""Signed-distance description of the procedural template head.

The head is a smooth constructive solid built from ellipsoids and round cones
(smooth unions and subtractions) laid out on adult proportions in the model
frame: millimetres, +x to the subject's left, +y up, +z out of the face (the
face looks down +z). The layout follows published facts about adult heads and
the mean head of a Basel-style model (nose tip near (0, 1, 132), chin tip near
(0, -70, 105), inner eye corners near (+-16.5, 32, 93), mouth corners near
(+-23.5, -33, 98)).

Bilateral features are built for ``x >= 0`` and mirrored by evaluating them
at ``|x|``; features that reach the midline are smooth-unioned with their
mirror image, so the field is even in ``x`` and smooth across ``x = 0``.

Points are passed as a tuple ``(x, y, z)`` of 1-D arrays (structure of arrays:
several times faster than (N, 3) rows in NumPy). Each primitive is evaluated
exactly only near its bounding sphere (see :func:`_culled`).

This module owns only geometry. It imports nothing from the project.
"""

from __future__ import annotations

import numpy as np

__all__ = ["EYE", "HEAD_BOUNDS", "LIP_BORDER", "Points", "head_sdf", "feature_sdfs", "as_points"]

Points = tuple[np.ndarray, np.ndarray, np.ndarray]

#: Box (mm) containing the head: ((xmin, ymin, zmin), (xmax, ymax, zmax)).
HEAD_BOUNDS = ((-98.0, -114.0, -98.0), (98.0, 150.0, 140.0))
#: The lips field is below this (mm) on the lips' red part (the vermilion).
LIP_BORDER = 0.6
#: The neck is cut flat at this height (mm).
NECK_CUT_Y = -106.0


class EYE:
    """Design constants of the left eye (x > 0); the right eye is its mirror image."""

    #: Eyeball centre (mm) and semi-axes (mm) in the eye frame.
    center = np.array([31.0, 32.5, 81.0])
    radii = np.array([14.0, 12.5, 12.5])
    #: Rotation about +y of the eye frame (rad): the lateral side recedes.
    yaw = np.radians(12.0)
    #: Palpebral fissure: centre (x, y), half width, upper and lower arc heights (mm).
    opening_center = np.array([30.0, 32.3])
    opening_half_width = 14.2
    opening_up = 6.2
    opening_down = 4.8
    #: Lid thickness over the eyeball (mm).
    lid = 1.6


def as_points(p: np.ndarray) -> Points:
    """(N, 3) array -> contiguous ``(x, y, z)`` float64 columns."""
    p = np.asarray(p, np.float64)
    return (
        np.ascontiguousarray(p[:, 0]),
        np.ascontiguousarray(p[:, 1]),
        np.ascontiguousarray(p[:, 2]),
    )


# -- combinators ---------------------------------------------------------------------
def _smin(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Cubic smooth minimum (C2, so no shading seams).

    The fillets are about as wide as those of a quadratic smooth minimum with
    radius ``k`` mm (it blends over ``1.6 k``).
    """
    k = 1.6 * k
    h = np.maximum(k - np.abs(a - b), 0.0) * (1.0 / k)
    return np.minimum(a, b) - h * h * h * (k / 6.0)


def _smax(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    return -_smin(-a, -b, k)


def _take(p: Points, mask: np.ndarray) -> Points:
    return (p[0][mask], p[1][mask], p[2][mask])


def _abs_x(p: Points) -> Points:
    return (np.abs(p[0]), p[1], p[2])


def _mirror(p: Points) -> Points:
    return (-p[0], p[1], p[2])


def _bilateral(p: Points, f, k: float = 0.0) -> np.ndarray:
    """``f`` (built for x > 0) and its mirror image; smooth union radius ``k`` if > 0."""
    if k <= 0:
        return f(_abs_x(p))
    return _smin(f(p), f(_mirror(p)), k)


#: Points farther than this (mm) outside a primitive's bounding sphere get the
#: distance to that sphere instead of the exact field. The margin exceeds the
#: blend radii plus the partial field values near the final surface, so the zero
#: set moves by less than a micrometre (the tests compare against no culling).
_CULL_MARGIN = 80.0

#: Boxes (mm) outside which the facial features and the ears cannot change the
#: zero set (each feature plus its blend radius lies inside); the ear box is in |x|.
_FACE_BOX = ((-80.0, -70.0, 45.0), (80.0, 85.0, 1e9))
_EAR_BOX = ((40.0, -48.0, -52.0), (1e9, 70.0, 56.0))


def _culled(p: Points, center, radius: float, f) -> np.ndarray:
    dx, dy, dz = p[0] - center[0], p[1] - center[1], p[2] - center[2]
    dist = np.sqrt(dx * dx + dy * dy + dz * dz) - radius
    near = dist < _CULL_MARGIN
    if near.all():
        return f(p)
    if near.any():
        dist[near] = f(_take(p, near))
    return dist


def _rot_y(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])


def _rot_x(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])


def _rot_z(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


# -- primitives -----------------------------------------------------------------------
def _ellipsoid(p: Points, c, r, rot: np.ndarray | None = None) -> np.ndarray:
    """Approximate signed distance to an ellipsoid (exact on the surface).

    ``rot`` maps local axes to the model frame (its columns are the local axes).
    """
    c = np.asarray(c, float)
    r = np.asarray(r, float)

    def f(q: Points) -> np.ndarray:
        dx, dy, dz = q[0] - c[0], q[1] - c[1], q[2] - c[2]
        if rot is not None:
            dx, dy, dz = (
                dx * rot[0, 0] + dy * rot[1, 0] + dz * rot[2, 0],
                dx * rot[0, 1] + dy * rot[1, 1] + dz * rot[2, 1],
                dx * rot[0, 2] + dy * rot[1, 2] + dz * rot[2, 2],
            )
        ax, ay, az = dx / r[0], dy / r[1], dz / r[2]
        k0 = np.sqrt(ax * ax + ay * ay + az * az)
        bx, by, bz = ax / r[0], ay / r[1], az / r[2]
        k1 = np.sqrt(bx * bx + by * by + bz * bz)
        return k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)

    return _culled(p, c, float(r.max()), f)


def _cone(p: Points, a, b, ra: float, rb: float) -> np.ndarray:
    """Approximate distance to the round cone from sphere (a, ra) to sphere (b, rb)."""
    a = np.asarray(a, float)
    ab = np.asarray(b, float) - a
    inv = 1.0 / float(ab @ ab)

    def f(q: Points) -> np.ndarray:
        dx, dy, dz = q[0] - a[0], q[1] - a[1], q[2] - a[2]
        t = np.clip((dx * ab[0] + dy * ab[1] + dz * ab[2]) * inv, 0.0, 1.0)
        ex, ey, ez = dx - t * ab[0], dy - t * ab[1], dz - t * ab[2]
        return np.sqrt(ex * ex + ey * ey + ez * ez) - (ra + t * (rb - ra))

    return _culled(p, a + 0.5 * ab, 0.5 * float(np.sqrt(ab @ ab)) + max(ra, rb), f)


def _chain(p: Points, pts, radii, k: float) -> np.ndarray:
    """Smooth union of round cones along a polyline."""
    d = _cone(p, pts[0], pts[1], radii[0], radii[1])
    for i in range(1, len(pts) - 1):
        d = _smin(d, _cone(p, pts[i], pts[i + 1], radii[i], radii[i + 1]), k)
    return d


# -- the head ---------------------------------------------------------------------------
def _skull(p: Points) -> np.ndarray:
    cranium = _ellipsoid(p, (0.0, 41.0, 0.0), (76.0, 101.0, 86.0))
    vault = _ellipsoid(p, (0.0, 77.0, 12.0), (67.0, 64.0, 84.0))
    forehead = _ellipsoid(p, (0.0, 60.0, 40.0), (66.0, 50.0, 67.0))
    return _smin(_smin(cranium, vault, 20.0), forehead, 20.0)


def _lower_head(p: Points) -> np.ndarray:
    midface = _ellipsoid(p, (0.0, 6.0, 48.0), (60.0, 48.0, 54.0))
    zyg = _bilateral(p, lambda q: _ellipsoid(q, (44.0, 14.0, 68.0), (20.0, 12.0, 20.0)))
    d = _smin(midface, zyg, 18.0)
    cheek = _bilateral(p, lambda q: _ellipsoid(q, (33.0, -4.0, 82.0), (20.0, 19.0, 14.0)))
    d = _smin(d, cheek, 18.0)
    muzzle = _ellipsoid(p, (0.0, -26.0, 78.0), (35.0, 24.0, 30.0))
    d = _smin(d, muzzle, 18.0)
    jaw = _smax(_ellipsoid(p, (0.0, -48.0, 0.0), (55.0, 28.0, 101.0)), -10.0 - p[2], 12.0)
    d = _smin(d, jaw, 18.0)
    submental = _ellipsoid(p, (0.0, -73.0, 55.0), (30.0, 10.0, 30.0))
    d = _smin(d, submental, 14.0)
    chin = _ellipsoid(p, (0.0, -62.0, 92.0), (16.0, 12.0, 12.5))
    d = _smin(d, chin, 10.0)
    neck = _cone(p, (0.0, -30.0, 0.0), (0.0, -150.0, 4.0), 52.0, 52.0)
    neck = _smax(neck, _ellipsoid(p, (0.0, -95.0, 2.0), (56.0, 90.0, 50.0)), 6.0)
    return _smin(d, neck, 18.0)


def _eye_frame(q: Points) -> Points:
    """Left-eye frame coordinates of ``q`` (u lateral, v up, w along the gaze)."""
    rot = _rot_y(np.degrees(EYE.yaw))
    dx, dy, dz = q[0] - EYE.center[0], q[1] - EYE.center[1], q[2] - EYE.center[2]
    return (
        dx * rot[0, 0] + dz * rot[2, 0],
        dy,
        dx * rot[0, 2] + dz * rot[2, 2],
    )


def _eyeball(p: Points) -> np.ndarray:
    return _bilateral(p, lambda q: _ellipsoid(_eye_frame(q), (0.0, 0.0, 0.0), EYE.radii))


def _lid_shell(p: Points) -> np.ndarray:
    return _bilateral(p, lambda q: _ellipsoid(_eye_frame(q), (0.0, 0.0, 0.0), EYE.radii + EYE.lid))


def _opening(p: Points) -> np.ndarray:
    """Palpebral fissure: an almond of two circular arcs, extruded along +z."""
    a, hu, hd = EYE.opening_half_width, EYE.opening_up, EYE.opening_down
    ru = (a * a + hu * hu) / (2 * hu)
    rd = (a * a + hd * hd) / (2 * hd)
    cx, cy = EYE.opening_center

    def f(q: Points) -> np.ndarray:
        u, v = q[0] - cx, q[1] - cy
        upper = np.hypot(u, v - (hu - ru)) - ru
        lower = np.hypot(u, v + (hd - rd)) - rd
        front = (EYE.center[2] + 3.0) - q[2]
        return np.maximum(np.maximum(upper, lower), front)

    return _bilateral(p, f)


def _socket(p: Points) -> np.ndarray:
    return _bilateral(p, lambda q: _ellipsoid(q, (31.0, 37.5, 99.0), (17.0, 11.0, 8.5)))


def _brows(p: Points) -> np.ndarray:
    def f(q: Points) -> np.ndarray:
        return _ellipsoid(q, (30.0, 48.5, 94.0), (21.0, 6.0, 6.0), _rot_y(27.0) @ _rot_z(-4.0))

    return _bilateral(p, f, k=10.0)


def _nose(p: Points) -> np.ndarray:
    bridge = _chain(
        p, [(0.0, 40.0, 96.0), (0.0, 24.0, 106.0), (0.0, 8.0, 119.5)], [7.0, 5.8, 6.3], 6.0
    )
    tip = _ellipsoid(p, (0.0, 1.0, 122.5), (8.5, 8.5, 9.0))
    d = _smin(bridge, tip, 7.0)
    alae = _bilateral(p, lambda q: _ellipsoid(q, (12.5, -7.5, 105.0), (7.0, 6.5, 8.5)), k=5.0)
    d = _smin(d, alae, 6.0)
    columella = _cone(p, (0.0, -6.0, 121.0), (0.0, -13.0, 114.0), 3.8, 4.0)
    d = _smin(d, columella, 3.5)
    base = _ellipsoid(p, (0.0, -2.0, 99.0), (18.0, 16.0, 14.0))
    return _smin(d, base, 8.0)


def _nostrils(p: Points) -> np.ndarray:
    return _bilateral(
        p, lambda q: _ellipsoid(q, (7.0, -13.6, 111.5), (3.6, 2.0, 5.5), _rot_y(25.0))
    )


def _upper_lip(p: Points) -> np.ndarray:
    def f(q: Points) -> np.ndarray:
        return _chain(
            q,
            [(0.0, -28.3, 111.3), (6.5, -27.6, 110.6), (15.0, -30.2, 106.0), (23.0, -33.5, 100.5)],
            [3.6, 3.8, 2.9, 1.8],
            4.0,
        )

    return _bilateral(p, f, k=4.0)


def _lower_lip(p: Points) -> np.ndarray:
    return _ellipsoid(p, (0.0, -37.0, 106.8), (20.5, 5.6, 6.0))


def _lips(p: Points) -> np.ndarray:
    # a nearly hard union leaves the crease of the closed mouth between the lips
    return _smin(_upper_lip(p), _lower_lip(p), 0.8)


def _ears(p: Points) -> np.ndarray:
    rot = _rot_y(-25.0) @ _rot_x(-10.0)

    def f(q: Points) -> np.ndarray:
        plate = _ellipsoid(q, (75.0, 11.0, -1.0), (5.0, 31.0, 18.0), rot)
        rim = _ellipsoid(q, (76.0, 11.0, -1.0), (6.5, 31.0, 18.0), rot)
        concha = _ellipsoid(q, (80.5, 7.0, 4.0), (5.0, 13.0, 9.0), rot)
        d = _smax(_smin(plate, rim, 2.0), -concha, 2.5)
        base = _ellipsoid(q, (64.0, 6.0, 8.0), (9.0, 22.0, 14.0))
        return _smin(d, base, 6.0)

    return _bilateral(p, f)


def feature_sdfs(p: np.ndarray) -> dict[str, np.ndarray]:
    """Fields of the named features that region masks are cut from.

    Parameters
    ----------
    p : (N, 3) float array, model frame (mm)

    Returns
    -------
    dict of str to (N,) float64
        ``eyeballs``, ``lids`` (lid shells), ``opening`` (eye fissures, extruded),
        ``lips``, ``upper_lip``, ``lower_lip``, ``brows``, ``nose``, ``ears``:
        approximate signed distances (mm), negative inside.
    """
    q = as_points(p)
    return {
        "eyeballs": _eyeball(q),
        "lids": _lid_shell(q),
        "opening": _opening(q),
        "lips": _lips(q),
        "upper_lip": _upper_lip(q),
        "lower_lip": _lower_lip(q),
        "brows": _brows(q),
        "nose": _nose(q),
        "ears": _ears(q),
    }


def head_sdf(p: Points | np.ndarray) -> np.ndarray:
    """Approximate signed distance (mm) to the template head, negative inside.

    Parameters
    ----------
    p : (N, 3) float array or ``(x, y, z)`` tuple of (N,) arrays
        Points in the model frame (mm).

    Returns
    -------
    (N,) float64
        Even in ``x``; smooth except along the lid margins and the neck cut.
    """
    q = p if isinstance(p, tuple) else as_points(p)
    d = _smin(_skull(q), _lower_head(q), 24.0)
    d = _in_box(q, d, _FACE_BOX, _with_face_features, abs_x=False)
    d = _in_box(q, d, _EAR_BOX, lambda r, e: _smin(e, _ears(r), 6.0), abs_x=True)
    return _smax(d, NECK_CUT_Y - q[1], 8.0)


def _in_box(q: Points, d: np.ndarray, box, f, *, abs_x: bool) -> np.ndarray:
    x = np.abs(q[0]) if abs_x else q[0]
    (x0, y0, z0), (x1, y1, z1) = box
    inside = (x >= x0) & (x <= x1) & (q[1] >= y0) & (q[1] <= y1) & (q[2] >= z0) & (q[2] <= z1)
    if inside.any():
        d = d.copy()
        d[inside] = f(_take(q, inside), d[inside])
    return d


def _with_face_features(q: Points, d: np.ndarray) -> np.ndarray:
    d = _smax(d, -_socket(q), 12.0)
    d = _smin(d, _brows(q), 14.0)
    d = _smin(d, _lid_shell(q), 3.0)
    d = _smax(d, -_opening(q), 1.2)
    d = _smin(d, _nose(q), 6.0)
    d = _smax(d, -_nostrils(q), 2.0)
    d = _smin(d, _lips(q), 5.0)
    return np.minimum(d, _eyeball(q))
