"""The interior of a render: face pixels away from its silhouette and its occlusion contours.

A ray cast decides per pixel centre which triangle is seen. Where the answer
jumps -- at the silhouette against the background and at self-occlusion
contours (the nose over the cheek, an ear over the scalp) -- a geometry move
of a hundredth of a pixel flips whole pixels between two unrelated colours,
so any likelihood summed over "the pixels the render covers" is a step
function of the geometry. :func:`interior_region` returns the pixels where the
render is a smooth function of the scene: hits at least ``erode`` pixels from
any miss and ``contour_band`` pixels from any depth jump between neighbouring
hits (a relative jump in the ray parameter larger than ``jump``).

This module imports only numpy and scipy.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = ["CONTOUR_SLOPE", "contour_jump", "depth_contours", "interior_region"]

#: Depth slope (tan of the angle between the surface and the image plane) beyond which two
#: neighbouring hits count as different surfaces: tan 80 degrees.
CONTOUR_SLOPE = 5.67


def contour_jump(focal_px: float) -> float:
    """Return the relative ray-parameter jump of :data:`CONTOUR_SLOPE` over one pixel.

    A surface at angle theta to the image plane changes the ray parameter by
    about ``tan(theta) / f`` of itself from one pixel to the next (``f`` the
    focal length in pixels): 0.006 at 250 pixels and the default camera.
    """
    return CONTOUR_SLOPE / float(focal_px)


def depth_contours(prim_id: np.ndarray, t: np.ndarray, width: int, height: int, *,
                   jump: float = 0.006) -> np.ndarray:
    """Return the (H, W) bool mask of hits next to a hit at another depth (occlusion contours).

    Two 4-neighbouring hits are on either side of a contour when their ray
    parameters differ by more than ``jump`` times the smaller (default 0.6 %
    of the distance: 7 mm at 1.2 m, a surface at 80 degrees across one pixel
    of the default camera at 250 pixels; :func:`contour_jump` for others).
    """
    hit = np.asarray(prim_id).reshape(height, width) >= 0
    depth = np.where(hit, np.asarray(t, np.float64).reshape(height, width), np.inf)
    out = np.zeros((height, width), bool)
    for axis in (0, 1):
        n = depth.shape[axis]
        a, b = np.take(depth, range(n - 1), axis), np.take(depth, range(1, n), axis)
        both = np.take(hit, range(n - 1), axis) & np.take(hit, range(1, n), axis)
        with np.errstate(invalid="ignore"):
            edge = both & (np.abs(a - b) > jump * np.minimum(a, b))
        lo, hi = [(0, 0), (0, 0)], [(0, 0), (0, 0)]
        lo[axis], hi[axis] = (0, 1), (1, 0)
        out |= np.pad(edge, lo) | np.pad(edge, hi)
    return out


def interior_region(prim_id: np.ndarray, t: np.ndarray, width: int, height: int, *,
                    erode: int = 2, contour_band: int = 2, jump: float = 0.006,
                    usable: np.ndarray | None = None) -> np.ndarray:
    """Return the (H W,) bool mask of interior face pixels of a ray cast (see the module notes).

    Parameters
    ----------
    prim_id : (H W,) int
        Triangle per pixel, -1 for a miss (row-major).
    t : (H W,) float
        Ray parameter of each hit (inf for misses).
    width, height : int
    erode : int
        Pixels kept away from the silhouette (4-connected erosion of the hits).
    contour_band : int
        Pixels kept away from occlusion contours (:func:`depth_contours`).
    jump : float
        Relative depth jump of a contour.
    usable : (H W,) bool, optional
        Further pixels to drop where False (e.g. saturated target pixels).

    Returns
    -------
    (H W,) bool
    """
    hit = np.asarray(prim_id).reshape(height, width) >= 0
    region = ndimage.binary_erosion(hit, iterations=erode, border_value=0) if erode else hit
    contours = depth_contours(prim_id, t, width, height, jump=jump)
    if contours.any() and contour_band:
        region &= ~ndimage.binary_dilation(contours, iterations=contour_band)
    elif contours.any():
        region &= ~contours
    region = region.reshape(-1)
    if usable is not None:
        region &= np.asarray(usable, bool).reshape(-1)
    return region
