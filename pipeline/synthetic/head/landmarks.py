"""Basel landmark names on the template head's vertices.

Every landmark is found geometrically on the mesh: extremal points (nose tip
= frontmost midline vertex, lip points = frontmost midline vertices on each lip,
stomion = the deepest midline point between them, ear top/bottom/back =
extremal ear vertices) or the front-facing vertex nearest to a designed
anchor in the frontal (x, y) projection (eye corners at the ends of the
palpebral fissure of :class:`pipeline.synthetic.head.head_sdf.EYE`, brow points, nose wings,
mouth corners, ...). ``center.*`` landmarks are midline vertices
(``symmetry[i] == i``); each ``right.*`` landmark is the mirror vertex of its
``left.*`` counterpart, so the landmark set is exactly symmetric.

Conventions: model frame in mm, +x is the subject's left (Basel ``left``).

Imports only :mod:`pipeline.synthetic.head.head_sdf`.
"""

from __future__ import annotations

import numpy as np

from pipeline.synthetic.head.head_sdf import EYE, LIP_BORDER, feature_sdfs

__all__ = ["LANDMARK_NAMES", "LFW_TLMS_NAMES", "place_landmarks"]

#: The 16 landmarks of the LFW ``.tlms`` files.
LFW_TLMS_NAMES = (
    "left.eyebrow.bend.lower", "right.eyebrow.bend.lower",
    "left.eyebrow.inner_lower", "right.eyebrow.inner_lower",
    "left.eye.corner_outer", "right.eye.corner_outer",
    "left.eye.corner_inner", "right.eye.corner_inner",
    "left.nose.wing.tip", "right.nose.wing.tip", "center.nose.tip",
    "left.lips.corner", "right.lips.corner",
    "center.lips.upper.outer", "center.lips.lower.outer", "center.chin.tip",
)  # fmt: skip

_A, _HU, _HD = EYE.opening_half_width, EYE.opening_up, EYE.opening_down
_CX, _CY = EYE.opening_center

#: Left-side anchors (x, y) found on the front-facing surface in frontal projection.
_FRONT_ANCHORS = {
    "eye.corner_inner": (_CX - _A + 0.6, _CY),
    "eye.corner_outer": (_CX + _A - 0.6, _CY),
    "eye.top": (_CX - 1.5, _CY + _HU),
    "eye.bottom": (_CX + 1.0, _CY - _HD),
    "eyebrow.inner_lower": (20.5, 47.5),
    "eyebrow.inner_upper": (22.0, 55.5),
    "eyebrow.bend.lower": (47.0, 46.5),
    "eyebrow.bend.upper": (42.0, 56.0),
    "nose.wing.tip": (15.0, -8.0),
    "nose.wing.outer": (19.0, -6.0),
    "lips.philtrum_ridge": (6.0, -24.5),
    "nasolabial_fold.center": (29.0, -21.0),
    "nasolabial_fold.bottom": (37.0, -38.0),
}

#: Left ear anchors (mm, 3D), searched among ear vertices.
_EAR_ANCHORS = {
    "ear.tragus.tip": (68.0, 4.0, 18.0),
    "ear.antihelix.center": (79.0, 9.0, -2.0),
    "ear.antihelix.tip": (75.0, -3.0, 9.0),
    "ear.lobule.center": (72.0, -10.0, 8.0),
    "ear.lobule.attachement": (66.0, -14.0, 12.0),
    "ear.helix.attachement": (75.0, 37.0, 6.0),
    "ear.helix.center": (84.0, 0.0, -10.0),
}

_SIDED = (
    *_FRONT_ANCHORS, *_EAR_ANCHORS, "lips.corner", "eye.pupil.center", "nose.hole.center",
    "ear.helix.top", "ear.lobule.tip", "ear.helix.outer",
)  # fmt: skip
_CENTER = (
    "center.nose.tip", "center.nose.attachement_to_philtrum", "center.lips.upper.outer",
    "center.lips.upper.inner", "center.lips.lower.inner", "center.lips.lower.outer",
    "center.chin.tip", "center.front.trichion",
)  # fmt: skip

#: Every landmark name the template carries.
LANDMARK_NAMES = tuple(
    sorted([f"{side}.{n}" for n in _SIDED for side in ("left", "right")] + list(_CENTER))
)


def _front_vertex(v: np.ndarray, facing: np.ndarray, xy: tuple[float, float]) -> int:
    """Front-facing vertex nearest to ``xy`` in frontal projection, on the frontmost layer."""
    d2 = (v[:, 0] - xy[0]) ** 2 + (v[:, 1] - xy[1]) ** 2
    cand = np.flatnonzero(facing & (d2 < 9.0))
    if cand.size == 0:
        cand = np.flatnonzero(facing)
        return int(cand[np.argmin(d2[cand])])
    front = cand[v[cand, 2] > v[cand, 2].max() - 4.0]
    return int(front[np.argmin(d2[front])])


def _nearest(v: np.ndarray, cand: np.ndarray, p) -> int:
    d2 = np.sum((v[cand] - np.asarray(p, float)) ** 2, axis=1)
    return int(cand[np.argmin(d2)])


def _midline_extreme(v: np.ndarray, mid: np.ndarray, ylo: float, yhi: float, direction) -> int:
    cand = mid[(v[mid, 1] >= ylo) & (v[mid, 1] <= yhi) & (v[mid, 2] > 60.0)]
    return int(cand[np.argmax(v[cand] @ np.asarray(direction, float))])


def place_landmarks(
    vertices: np.ndarray, triangles: np.ndarray, symmetry: np.ndarray
) -> dict[str, int]:
    """Landmark name -> vertex index on the template mesh.

    Parameters
    ----------
    vertices : (n, 3) float64
        Template vertices, model frame (mm), exactly symmetric.
    triangles : (m, 3) int array
        Counter-clockwise from outside.
    symmetry : (n,) int64
        Mirror-vertex map.

    Returns
    -------
    dict of str to int
        All names in :data:`LANDMARK_NAMES` (Basel names; ``left`` = +x).
    """
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles)
    sym = np.asarray(symmetry)
    fn = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    nz = np.zeros(len(v))
    nn = np.zeros(len(v))
    for j in range(3):
        nz += np.bincount(t[:, j], weights=fn[:, 2], minlength=len(v))
        nn += np.bincount(t[:, j], weights=np.linalg.norm(fn, axis=1), minlength=len(v))
    facing = (nz > 0.2 * nn) & (v[:, 2] > 60.0)
    left = v[:, 0] > 0.0
    mid = np.flatnonzero(sym == np.arange(len(v)))
    feats = feature_sdfs(v)

    out: dict[str, int] = {}
    for name, xy in _FRONT_ANCHORS.items():
        out["left." + name] = _front_vertex(v, facing & left, xy)

    ball = np.flatnonzero(left & (feats["eyeballs"] < 0.3) & (feats["opening"] < 0.0))
    on_ball = np.zeros(len(v), bool)
    on_ball[ball] = True
    out["left.eye.pupil.center"] = _front_vertex(v, on_ball, (EYE.center[0] + 0.5, EYE.center[1]))
    nostril_wall = np.flatnonzero(left & (v[:, 1] < -8.0) & (v[:, 2] > 100.0) & (v[:, 0] < 12.0))
    out["left.nose.hole.center"] = _nearest(v, nostril_wall, (7.0, -13.6, 111.5))

    ear = np.flatnonzero(left & (feats["ears"] < 1.0) & (v[:, 0] > 60.0))
    for name, p in _EAR_ANCHORS.items():
        out["left." + name] = _nearest(v, ear, p)
    out["left.ear.helix.top"] = int(ear[np.argmax(v[ear, 1])])
    out["left.ear.lobule.tip"] = int(ear[np.argmin(v[ear, 1])])
    out["left.ear.helix.outer"] = int(ear[np.argmax(v[ear] @ np.array([0.3, 0.0, -1.0]))])

    for name in [k for k in out if k.startswith("left.")]:
        out["right." + name[5:]] = int(sym[out[name]])

    lip_zone = feats["lips"] < LIP_BORDER
    mid_lip = mid[lip_zone[mid] & (v[mid, 2] > 90.0)]
    upper = mid_lip[feats["upper_lip"][mid_lip] < feats["lower_lip"][mid_lip]]
    up = int(upper[np.argmax(v[upper, 2])])
    low = int(mid_lip[np.argmin(v[mid_lip, 1])])
    # the closed mouth's crease is where the two lip bodies meet
    crease = np.abs(feats["upper_lip"] - feats["lower_lip"])
    stomion = int(mid_lip[np.argmin(crease[mid_lip])])
    # mouth corner: the lateral end of the crease, where the lips sink into the skin
    on_crease = np.flatnonzero(left & (crease < 0.8) & (feats["lips"] < 3.0) & facing)
    corner = int(on_crease[np.argmax(v[on_crease, 0])])
    out["left.lips.corner"] = corner
    out["right.lips.corner"] = int(sym[corner])
    tip = _midline_extreme(v, mid, -20.0, 20.0, (0.0, 0.0, 1.0))
    below_tip = mid[(v[mid, 1] < v[tip, 1] - 5.0) & (v[mid, 1] > v[up, 1]) & (v[mid, 2] > 95.0)]
    # subnasale: the deepest point of the concave corner between columella and lip
    chord = v[up] - v[tip]
    chord_n = np.array([0.0, -chord[2], chord[1]]) / np.hypot(chord[1], chord[2])
    subnasale = int(below_tip[np.argmax((v[below_tip] - v[tip]) @ chord_n)])
    out.update(
        {
            "center.nose.tip": tip,
            "center.nose.attachement_to_philtrum": subnasale,
            "center.lips.upper.outer": up,
            "center.lips.upper.inner": stomion,
            "center.lips.lower.inner": stomion,
            "center.lips.lower.outer": low,
            "center.chin.tip": _midline_extreme(v, mid, -85.0, -50.0, (0.0, -0.45, 1.0)),
        }
    )
    front_mid = mid[v[mid, 2] > 40.0]
    trich = front_mid[np.abs(v[front_mid, 1] - 89.0) < 3.0]
    out["center.front.trichion"] = int(trich[np.argmax(v[trich, 2])])
    return dict(sorted(out.items()))
