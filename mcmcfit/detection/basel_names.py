"""Which Face Mesh point is which Basel landmark, and how far each can be trusted.

Indices are those of MediaPipe's canonical 468-point face mesh topology; names are
the Basel (scalismo-faces ``.tlms``) names, where "left" is the subject's left
(image right in a photograph that is not mirrored). Each was checked on
pictures of the mesh over photographs (``mcmcfit landmarks IMAGE --png``). The
sigma factor scales the fit's landmark noise: eyebrows and the chin are placed
least reliably by Face Mesh (they sit on soft contours), the eye and mouth
corners most reliably.

This module imports nothing from the project.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["BASEL_POINTS", "BaselPoint", "mirrored_name"]


class BaselPoint(NamedTuple):
    """One Basel landmark read from the mesh.

    Attributes
    ----------
    name : str
        Basel name.
    index : int
        Face Mesh point index.
    sigma_factor : float
        Multiplies the fit's landmark sigma for this point.
    """

    name: str
    index: int
    sigma_factor: float


#: The Basel landmarks read from the mesh (subject's right, then left, then centre).
BASEL_POINTS: tuple[BaselPoint, ...] = (
    BaselPoint("right.eye.corner_outer", 33, 1.0),
    BaselPoint("right.eye.corner_inner", 133, 1.0),
    BaselPoint("right.eye.top", 159, 1.25),
    BaselPoint("right.eye.bottom", 145, 1.25),
    BaselPoint("right.eyebrow.inner_upper", 107, 2.0),
    BaselPoint("right.eyebrow.inner_lower", 55, 2.0),
    BaselPoint("right.eyebrow.bend.upper", 105, 2.0),
    BaselPoint("right.eyebrow.bend.lower", 52, 2.0),
    BaselPoint("right.nose.wing.outer", 64, 1.25),
    BaselPoint("right.lips.corner", 61, 1.0),
    BaselPoint("right.lips.philtrum_ridge", 37, 1.5),
    BaselPoint("left.eye.corner_outer", 263, 1.0),
    BaselPoint("left.eye.corner_inner", 362, 1.0),
    BaselPoint("left.eye.top", 386, 1.25),
    BaselPoint("left.eye.bottom", 374, 1.25),
    BaselPoint("left.eyebrow.inner_upper", 336, 2.0),
    BaselPoint("left.eyebrow.inner_lower", 285, 2.0),
    BaselPoint("left.eyebrow.bend.upper", 334, 2.0),
    BaselPoint("left.eyebrow.bend.lower", 282, 2.0),
    BaselPoint("left.nose.wing.outer", 294, 1.25),
    BaselPoint("left.lips.corner", 291, 1.0),
    BaselPoint("left.lips.philtrum_ridge", 267, 1.5),
    BaselPoint("center.nose.tip", 4, 1.25),
    BaselPoint("center.nose.attachement_to_philtrum", 2, 1.5),
    BaselPoint("center.lips.upper.outer", 0, 1.25),
    BaselPoint("center.lips.upper.inner", 13, 1.5),
    BaselPoint("center.lips.lower.inner", 14, 1.5),
    BaselPoint("center.lips.lower.outer", 17, 1.5),
    BaselPoint("center.chin.tip", 152, 2.0),
)


def mirrored_name(name: str) -> str:
    """Return the name of the landmark's mirror image (left <-> right; centre unchanged)."""
    side, _, rest = name.partition(".")
    return {"left": "right." + rest, "right": "left." + rest}.get(side, name)
