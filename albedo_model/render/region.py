"""The interior of a render: face pixels away from its silhouette and its occlusion contours.

A ray cast decides per pixel centre which triangle is seen. Where the answer
jumps -- at the silhouette against the background and at self-occlusion
contours (the nose over the cheek, an ear over the scalp) -- a geometry move
of a hundredth of a pixel flips whole pixels between two unrelated colours,
so any likelihood summed over "the pixels the render covers" is a step
function of the geometry. :func:`interior_region` returns the pixels where the
render is a smooth function of the scene: hits at least ``erode`` pixels from
any miss and ``contour_band`` pixels from any occlusion contour.

Occlusion contours are found two ways, and either suffices to exclude a pixel:

* a depth jump between neighbouring hits (a relative jump in the ray
  parameter larger than ``jump``; :func:`depth_contours`): one surface far in
  front of another;
* the visible **fold edges** of the mesh (:func:`fold_contours`): mesh edges
  between a triangle that faces the camera and one that faces away are where
  the surface turns out of sight, so every occlusion contour of a mesh lies on
  them. A fold can hide a sliver of surface with almost no depth step (an
  eyelid over the eye corner: 1 mm at 1.2 m, far below any depth threshold),
  yet the colour jumps there as at any contour.

This module imports :mod:`albedo_model.camera`, numpy and scipy.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from albedo_model.camera import eye_position_model, project, to_eye, towards_camera_model
from albedo_model.params import RenderParameter

__all__ = ["CONTOUR_SLOPE", "contour_jump", "depth_contours", "fold_contours", "fold_edges",
           "interior_region"]

#: Spacing (pixels) of the points a fold edge is drawn with.
_FOLD_SPACING = 0.25

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


def fold_edges(vertices: np.ndarray, triangles: np.ndarray, viewpoint: np.ndarray, *,
               orthographic: bool = False) -> np.ndarray:
    """Return the mesh edges where the surface turns away from the camera, (k, 2) vertex ids.

    An edge is a fold when one of its two triangles faces the viewpoint and the
    other faces away, or when it borders one triangle only (a hole's or the
    mesh's rim).

    Parameters
    ----------
    vertices : (V, 3) float
        Posed vertices, in the frame of ``viewpoint``.
    triangles : (F, 3) int
        Counter-clockwise seen from outside.
    viewpoint : (3,) float
        The camera centre, or with ``orthographic`` the direction towards the camera.
    orthographic : bool
    """
    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles, np.int64)
    normal = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])
    towards = (np.broadcast_to(np.asarray(viewpoint, np.float64), normal.shape)
               if orthographic else np.asarray(viewpoint, np.float64) - v[tri[:, 0]])
    front = np.einsum("ij,ij->i", normal, towards) > 0.0
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    faces = np.tile(np.arange(tri.shape[0]), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, faces = edges[order], faces[order]
    first = np.ones(edges.shape[0], bool)
    first[1:] = np.any(edges[1:] != edges[:-1], axis=1)
    start = np.flatnonzero(first)
    count = np.diff(np.append(start, edges.shape[0]))
    facing = front[faces]
    n_front = np.add.reduceat(facing.astype(np.int64), start)
    fold = (count == 1) | ((n_front > 0) & (n_front < count))
    return edges[start[fold]]


def fold_contours(params: RenderParameter, vertices: np.ndarray, triangles: np.ndarray,
                  t: np.ndarray, *, tolerance: float = 0.006) -> np.ndarray:
    """Return the (H, W) bool mask of pixels a visible fold edge crosses (see the module notes).

    Each fold edge (:func:`fold_edges`) is drawn as points every quarter
    pixel; a point counts where it is not hidden: its ray parameter is at most
    ``(1 + tolerance)`` times the smallest hit's among the 3 x 3 pixels around
    it (a fold behind the face, at the back of the head or behind the nose, is
    centimetres deeper than the surface seen there).

    Parameters
    ----------
    params : RenderParameter
        The scene (pose, view, camera, image size).
    vertices : (V, 3) float
        The posed shape in the model frame (``model.shape_instance``).
    triangles : (F, 3) int
    t : (H W,) float
        Ray parameters of the scene's ray cast (inf for misses; ``t = eye depth - near``).
    tolerance : float
        Relative depth margin of the visibility test.
    """
    w, h = int(params.image_size.width), int(params.image_size.height)
    out = np.zeros((h, w), bool)
    ortho = bool(params.camera.orthographic)
    viewpoint = (towards_camera_model(params.pose, params.view) if ortho
                 else eye_position_model(params.pose, params.view))
    edges = fold_edges(vertices, triangles, viewpoint, orthographic=ortho)
    if edges.size == 0:
        return out
    v = np.asarray(vertices, np.float64)
    ends_px, _ = project(v[edges.reshape(-1)], params.pose, params.view, params.camera,
                         params.image_size)
    ends_px = ends_px.reshape(-1, 2, 2)
    length = np.linalg.norm(ends_px[:, 1] - ends_px[:, 0], axis=1)
    n = np.maximum(1, np.ceil(np.nan_to_num(length, nan=0.0) / _FOLD_SPACING)).astype(np.int64)
    n = np.minimum(n, 4 * (w + h))  # an edge through the camera plane: bounded work
    edge_of = np.repeat(np.arange(edges.shape[0]), n + 1)
    frac = (np.arange(edge_of.size) - np.repeat(np.cumsum(n + 1) - (n + 1), n + 1)) / np.repeat(n, n + 1)
    pts = v[edges[edge_of, 0]] + frac[:, None] * (v[edges[edge_of, 1]] - v[edges[edge_of, 0]])
    px, _ = project(pts, params.pose, params.view, params.camera, params.image_size)
    depth = -to_eye(pts, params.pose, params.view)[:, 2] - float(params.camera.near)
    ij = np.rint(np.nan_to_num(px, nan=-1.0, posinf=-1.0, neginf=-1.0)).astype(np.int64)
    inside = ((depth > 0.0) & (ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0)
              & (ij[:, 1] < h))
    ij, depth = ij[inside], depth[inside]
    nearest = ndimage.minimum_filter(np.asarray(t, np.float64).reshape(h, w), size=3,
                                     mode="constant", cval=np.inf)
    seen = depth <= (1.0 + tolerance) * nearest[ij[:, 1], ij[:, 0]]
    out[ij[seen, 1], ij[seen, 0]] = True
    return out


def interior_region(prim_id: np.ndarray, t: np.ndarray, width: int, height: int, *,
                    erode: int = 2, contour_band: int = 2, jump: float = 0.006,
                    usable: np.ndarray | None = None,
                    folds: np.ndarray | None = None) -> np.ndarray:
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
    folds : (H, W) bool, optional
        Pixels on visible fold edges (:func:`fold_contours`), kept ``contour_band``
        pixels away from like the depth contours.

    Returns
    -------
    (H W,) bool
    """
    hit = np.asarray(prim_id).reshape(height, width) >= 0
    region = ndimage.binary_erosion(hit, iterations=erode, border_value=0) if erode else hit
    contours = depth_contours(prim_id, t, width, height, jump=jump)
    if folds is not None:
        contours = contours | (np.asarray(folds, bool).reshape(height, width) & hit)
    if contours.any() and contour_band:
        region &= ~ndimage.binary_dilation(contours, iterations=contour_band)
    elif contours.any():
        region &= ~contours
    region = region.reshape(-1)
    if usable is not None:
        region &= np.asarray(usable, bool).reshape(-1)
    return region
