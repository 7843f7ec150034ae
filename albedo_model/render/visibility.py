"""What the light and the camera see of the surface: cast shadows, visible landmarks.

This module imports only :mod:`albedo_model.camera`, :mod:`albedo_model.params`
and :mod:`albedo_model.render.raycast`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.camera import euler_rotation, eye_position_model, project, towards_camera_model
from albedo_model.params import RenderParameter
from albedo_model.render.raycast import RayCaster, RayHits, visible_points

__all__ = ["directional_visibility", "landmark_pixels"]


def directional_visibility(hits: RayHits, vertices: np.ndarray, triangles: np.ndarray, pose,
                           direction, caster: RayCaster) -> np.ndarray:
    """Visibility of a directional light at every pixel's surface point.

    Parameters
    ----------
    hits : RayHits
        Primary hits of the pixels (model frame).
    vertices : (n, 3) float array, model frame
        The instance the hits were cast against (and ``caster`` holds).
    triangles : (m, 3) int array
    pose : Pose
        World-from-model pose (the light direction is given in the world frame).
    direction : (3,) float
        Direction towards the light, world frame.
    caster : RayCaster
        Scene of ``vertices``.

    Returns
    -------
    (P,) float32
        1 where the light reaches the surface point (and on misses), 0 where the
        mesh occludes it.
    """
    idx = np.flatnonzero(hits.prim_id >= 0)
    visibility = np.ones(len(hits.prim_id), np.float32)
    if idx.size == 0:
        return visibility
    tri = np.asarray(triangles)[hits.prim_id[idx]]
    u, w = hits.bary[idx, :1], hits.bary[idx, 1:]
    pts = (1.0 - u - w) * vertices[tri[:, 0]] + u * vertices[tri[:, 1]] + w * vertices[tri[:, 2]]
    r = euler_rotation(pose.roll, pose.yaw, pose.pitch)
    l_world = np.asarray(direction, np.float64)
    l_model = r.T @ (l_world / np.linalg.norm(l_world))
    # start just off the surface towards the light, so the point's own triangle is not hit
    start = (pts + 1e-4 * caster.scale * l_model).astype(np.float32)
    occluded = caster.occluded(start, l_model.reshape(1, 3).astype(np.float32))
    visibility[idx[occluded]] = 0.0
    return visibility


def landmark_pixels(landmark_vertices: dict, vertices: np.ndarray, params: RenderParameter,
                    caster: RayCaster, names=None) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Projected landmarks of an instance, with visibility.

    Parameters
    ----------
    landmark_vertices : mapping of str to int
        Vertex of each landmark (:attr:`MorphableModel.landmark_vertices`).
    vertices : (n, 3) float array, model frame
        The instance ``caster`` holds.
    params : RenderParameter
    caster : RayCaster
    names : iterable of str, optional
        Landmark names (default: all); names without a vertex are skipped.

    Returns
    -------
    names : list of str
    pixels : (k, 2) float64, (x right, y down)
    visible : (k,) bool
        In front of the camera, inside the image and not occluded by the surface.
    """
    lv = landmark_vertices
    names = list(lv) if names is None else [n for n in names if n in lv]
    if not names:
        return [], np.zeros((0, 2)), np.zeros(0, bool)
    pts = np.asarray(vertices)[np.array([lv[n] for n in names])]
    p = params
    pixels, depth = project(pts, p.pose, p.view, p.camera, p.image_size)
    if p.camera.orthographic:
        vis = visible_points(pts, None, caster, direction=towards_camera_model(p.pose, p.view))
    else:
        vis = visible_points(pts, eye_position_model(p.pose, p.view), caster)
    w, h = p.image_size
    inside = ((pixels[:, 0] >= -0.5) & (pixels[:, 0] <= w - 0.5)
              & (pixels[:, 1] >= -0.5) & (pixels[:, 1] <= h - 0.5) & (depth > 0) & (depth < 1))
    return names, pixels, vis & inside
