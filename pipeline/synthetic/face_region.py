"""The face region of the template head: a face mask like BFM 2017's ``face12``.

The template head (:mod:`pipeline.synthetic.head.template_head`) is a whole
head: scalp, ears, neck. Fitted to a photograph, those parts are asked to
explain hair and background. :func:`face_region` chooses the vertices of the
face alone, as the ``face12`` crop of the Basel Face Model 2017 does: forehead
to chin, ear to ear in front of the ears; no scalp, no ears, no neck below the
chin; the eyeballs and the lips are kept.

The region is cut from the template's own landmarks (model frame, mm: +x the
subject's left, +y up, +z out of the face), not from listed vertex ids, by
three surfaces that depend on ``|x|``, ``y`` and ``z`` only:

* **in front of the ears**: ``z > z(tragus) + 7 mm``, a coronal plane just in
  front of the ear's base (the ear region ends about 3 mm in front of the
  tragus tip);
* **below the hairline**: ``y < y(trichion) + 2 mm - (y(trichion) - y(helix
  top)) (|x| / x(tragus))^2``, a parabola just above the trichion (the
  hairline on the midline, kept with its landmark) that drops to the height of
  the top of the ear at the sideburns;
* **above the jaw line**: in the side view a straight line from a point under
  the chin (14 mm below and 25 mm behind the chin tip, which keeps the chin's
  underside) up to a point below the ear (28 mm below the lobule tip, 15 mm in
  front of the tragus), roughly the lower border of the mandible; in front of
  the first point the bound stays at its height. The neck and the throat
  below the cervicomental angle fall below it.

The ear region of :func:`pipeline.synthetic.head.regions.region_masks` is
removed as well (it lies behind the coronal plane anyway). The mask is then
made mirror-symmetric, restricted to vertices that belong to a triangle with
all three corners in it, and to the largest edge-connected piece of those
triangles, so the crop is one clean surface patch without isolated vertices.

This module imports only :mod:`albedo_model.errors` and SciPy; it reads a
:class:`~pipeline.synthetic.head.template_head.TemplateHead` (or any object
with its ``vertices``, ``triangles``, ``symmetry``, ``landmarks`` and
``regions``) without importing it.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from albedo_model.errors import InputError

__all__ = ["FACE_REGION_LANDMARKS", "FACE_REGION_RULE", "face_region"]

#: Landmarks the cut surfaces are anchored on (left side; the region is symmetric).
FACE_REGION_LANDMARKS = (
    "center.front.trichion", "center.chin.tip", "left.ear.tragus.tip", "left.ear.helix.top",
    "left.ear.lobule.tip",
)  # fmt: skip

#: Offsets (mm) of the cut surfaces from their landmarks (see the module docstring).
_FRONT_OF_TRAGUS = 7.0
_ABOVE_TRICHION = 2.0
_UNDER_CHIN = (14.0, 25.0)   # below, behind the chin tip
_BELOW_LOBULE = 28.0          # the jaw line's far end: below the lobule tip ...
_GONION_FRONT = 15.0          # ... and in front of the tragus tip

#: One-line description of the rule (recorded in the cropped model's metadata).
FACE_REGION_RULE = (
    f"template face region (pipeline.synthetic.face_region): z > tragus + {_FRONT_OF_TRAGUS:g} mm, "
    "below the trichion-to-helix-top parabola, above the chin-to-gonion jaw line, no ears, "
    "largest connected patch"
)


def _largest_patch(mask: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Vertices of the largest edge-connected set of triangles lying entirely in ``mask``."""
    inside = triangles[np.all(mask[triangles], axis=1)]
    keep = np.zeros_like(mask)
    if len(inside) == 0:
        return keep
    n = len(mask)
    a = np.concatenate([inside[:, 0], inside[:, 1], inside[:, 2]])
    b = np.concatenate([inside[:, 1], inside[:, 2], inside[:, 0]])
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    used = np.unique(inside)
    sizes = np.bincount(label[used], minlength=label.max() + 1)
    keep[used[label[used] == np.argmax(sizes)]] = True
    return keep


def face_region(head) -> np.ndarray:
    """Choose the face vertices of the template head (a ``face12``-like mask).

    Parameters
    ----------
    head : TemplateHead
        Or any object with ``vertices`` (n, 3), ``triangles`` (m, 3),
        ``symmetry`` (n,), ``landmarks`` (name -> vertex index, with the names
        of :data:`FACE_REGION_LANDMARKS`) and ``regions`` (with ``ears``).

    Returns
    -------
    (n,) bool array
        Mirror-symmetric (``mask == mask[symmetry]``); every vertex in it
        belongs to a triangle whose three corners are in it, and those
        triangles form one connected surface.

    Raises
    ------
    InputError
        A landmark the rule needs is missing, or nothing is left.
    """
    v = np.asarray(head.vertices, np.float64)
    tri = np.asarray(head.triangles, np.int64)
    sym = np.asarray(head.symmetry, np.int64)
    missing = [name for name in FACE_REGION_LANDMARKS if name not in head.landmarks]
    if missing:
        raise InputError(f"the face region needs the landmarks {', '.join(missing)}")
    trichion, chin, tragus, helix_top, lobule = (
        v[int(head.landmarks[name])] for name in FACE_REGION_LANDMARKS
    )
    ax, y, z = np.abs(v[:, 0]), v[:, 1], v[:, 2]

    in_front = z > tragus[2] + _FRONT_OF_TRAGUS
    hairline = trichion[1] + _ABOVE_TRICHION - (trichion[1] - helix_top[1]) * (ax / abs(tragus[0])) ** 2
    below_hair = y < hairline
    # the jaw line in the side view (z, y): from under the chin back up to below the ear
    z0, y0 = chin[2] - _UNDER_CHIN[1], chin[1] - _UNDER_CHIN[0]
    z1, y1 = tragus[2] + _GONION_FRONT, lobule[1] - _BELOW_LOBULE
    jaw = np.where(z >= z0, y0, y0 + (y1 - y0) * (z0 - z) / (z0 - z1))
    above_jaw = y > jaw

    mask = in_front & below_hair & above_jaw & ~np.asarray(head.regions["ears"], bool)
    while True:  # a fixed point: symmetric, one patch, no vertex outside its triangles
        new = _largest_patch(mask & mask[sym], tri)
        if np.array_equal(new, mask):
            break
        mask = new
    if not mask.any():
        raise InputError("the face region of this head is empty")
    return mask
