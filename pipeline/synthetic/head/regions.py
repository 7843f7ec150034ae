"""Region masks on the template head (for albedo and specular maps).

Masks are cut from the feature fields of :mod:`pipeline.synthetic.head.head_sdf` and from
simple anthropometric zones in the model frame (mm, +x subject's left, +y up,
+z out of the face). Every mask is mirror-symmetric (``mask == mask[symmetry]``)
because it depends on ``|x|`` only.

Regions: ``eyeballs`` (exposed eyeball surface), ``lips`` (vermilion),
``brows`` (eyebrow hair band), ``beard`` (moustache, chin, jaw and upper neck
front), ``nose``, ``forehead``, ``cheeks``, ``ears`` and ``skin`` (everything
but the eyeballs). Regions other than ``skin`` may overlap only where stated:
``beard`` excludes lips and nose; ``cheeks`` and ``forehead`` exclude brows,
nose and eyes.

Imports only :mod:`pipeline.synthetic.head.head_sdf`.
"""

from __future__ import annotations

import numpy as np

from pipeline.synthetic.head.head_sdf import LIP_BORDER, feature_sdfs

__all__ = ["REGION_NAMES", "region_masks"]

REGION_NAMES = ("eyeballs", "lips", "brows", "beard", "nose", "forehead", "cheeks", "ears", "skin")

#: Eyebrow centre line (|x|, y) and half heights (mm), on the front-facing skin.
_BROW_LINE = np.array([(16.0, 50.5), (26.0, 53.0), (38.0, 53.0), (48.0, 50.5), (55.0, 46.5)])
_BROW_HALF = np.array([3.8, 4.4, 4.0, 3.2, 2.0])


def _band_distance(px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Distance from (px, py) to the brow polyline, in units of the local half height."""
    best = np.full(px.shape, np.inf)
    for (a, b), (ha, hb) in zip(
        zip(_BROW_LINE[:-1], _BROW_LINE[1:]), zip(_BROW_HALF[:-1], _BROW_HALF[1:])
    ):
        ab = b - a
        t = np.clip(((px - a[0]) * ab[0] + (py - a[1]) * ab[1]) / (ab @ ab), 0.0, 1.0)
        d = np.hypot(px - a[0] - t * ab[0], py - a[1] - t * ab[1]) / (ha + t * (hb - ha))
        best = np.minimum(best, d)
    return best


def region_masks(
    vertices: np.ndarray, triangles: np.ndarray, symmetry: np.ndarray
) -> dict[str, np.ndarray]:
    """Boolean region masks on the template vertices.

    Parameters
    ----------
    vertices : (n, 3) float64
        Template vertices, model frame (mm).
    triangles : (m, 3) int array
        Counter-clockwise from outside (used for vertex normals).
    symmetry : (n,) int64
        Mirror-vertex map; masks are symmetrised with it.

    Returns
    -------
    dict of str to (n,) bool
        The regions of :data:`REGION_NAMES`.
    """
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles)
    sym = np.asarray(symmetry)
    fn = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    nrm = np.zeros_like(v)
    for j in range(3):
        for c in range(3):
            nrm[:, c] += np.bincount(t[:, j], weights=fn[:, c], minlength=len(v))
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    f = feature_sdfs(v)
    ax, y, z = np.abs(v[:, 0]), v[:, 1], v[:, 2]

    eyeballs = (f["eyeballs"] < 0.3) & (f["opening"] < 0.3)
    eye_zone = f["lids"] < 3.0
    lips = (f["lips"] < LIP_BORDER) & (z > 90.0)
    nose = (f["nose"] < 1.5) & (z > 96.0) & (y > -17.0) & (y < 42.0) & (ax < 24.0)
    nose &= ~eye_zone
    brows = (_band_distance(ax, y) < 1.0) & (nrm[:, 2] > 0.1) & (z > 60.0) & ~eye_zone
    beard_top = -14.0 + 0.45 * np.maximum(ax - 20.0, 0.0)
    beard = (y < beard_top) & (y > -100.0) & (z > 8.0) & ~lips & ~nose & (ax < 68.0)
    beard &= ~((y < -78.0) & (z < 30.0))  # no beard on the back of the neck
    forehead = (((ax / 50.0) ** 2 + ((y - 76.0) / 22.0) ** 2) < 1.0) & (z > 40.0) & ~brows
    cheek_ellipse = ((ax - 40.0) / 19.0) ** 2 + ((y + 2.0) / 22.0) ** 2 < 1.0
    cheeks = cheek_ellipse & (z > 50.0) & ~nose & ~lips & ~eye_zone & ~eyeballs
    ears = (f["ears"] < 1.5) & (ax > 58.0)
    out = {
        "eyeballs": eyeballs,
        "lips": lips,
        "brows": brows,
        "beard": beard,
        "nose": nose,
        "forehead": forehead,
        "cheeks": cheeks,
        "ears": ears,
    }
    # exact mirror symmetry (the fields are even in x up to rounding)
    out = {k: m & m[sym] for k, m in out.items()}
    out["skin"] = ~out["eyeballs"]
    return out
