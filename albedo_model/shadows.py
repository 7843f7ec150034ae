"""Cast shadows of the directional light: one occlusion ray per face pixel.

This module imports only :mod:`albedo_model.camera` and :mod:`albedo_model.raycast`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.camera import euler_rotation
from albedo_model.raycast import RayCaster, RayHits

__all__ = ["directional_visibility"]


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
