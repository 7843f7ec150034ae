"""What the light and the camera see of the surface: cast shadows, visible landmarks.

This module imports only :mod:`albedo_model.camera`, :mod:`albedo_model.errors`,
:mod:`albedo_model.params` and :mod:`albedo_model.render.raycast`.
"""

from __future__ import annotations

import math

import numpy as np

from albedo_model.camera import euler_rotation, eye_position_model, project, towards_camera_model
from albedo_model.errors import InputError
from albedo_model.params import RenderParameter
from albedo_model.render.raycast import RayCaster, RayHits, visible_points

__all__ = ["directional_visibility", "landmark_pixels", "shadow_directions"]

#: Golden angle (radians): successive soft-shadow rays turn by it around the light direction.
_GOLDEN = math.pi * (3.0 - math.sqrt(5.0))


def shadow_directions(direction, rays: int = 1, spread_deg: float = 0.0) -> np.ndarray:
    """Return the unit directions of shadow rays towards a light of angular radius ``spread_deg``.

    Parameters
    ----------
    direction : (3,) float
        Direction towards the light's centre (any length).
    rays : int
        Rays per surface point; 1 gives the centre alone (a hard shadow).
    spread_deg : float
        Angular radius of the light (degrees) that the rays sample.

    Returns
    -------
    (rays, 3) float64
        A fixed spiral over the light's disc (ray ``i`` at radius
        ``spread sqrt((i + 1/2) / rays)``, turned by the golden angle from the last),
        so that the visibility is a deterministic function of the direction:
        the likelihood an MH test compares must not change between two calls
        at the same state, as random jitter would.
    """
    d = np.asarray(direction, np.float64).reshape(3)
    d = d / np.linalg.norm(d)
    if int(rays) < 1:
        raise InputError(f"shadow rays must be >= 1, got {rays}")
    if int(rays) == 1 or spread_deg <= 0.0:
        return np.tile(d, (int(rays), 1))
    helper = np.eye(3)[int(np.argmin(np.abs(d)))]
    e1 = np.cross(d, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    i = np.arange(int(rays))
    radius = math.tan(math.radians(spread_deg)) * np.sqrt((i + 0.5) / rays)
    turn = i * _GOLDEN
    out = d + radius[:, None] * (np.cos(turn)[:, None] * e1 + np.sin(turn)[:, None] * e2)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def directional_visibility(hits: RayHits, vertices: np.ndarray, triangles: np.ndarray, pose,
                           direction, caster: RayCaster, *, rays: int = 1,
                           spread_deg: float = 0.0) -> np.ndarray:
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
    rays, spread_deg : int, float
        Shadow rays per surface point over a light of this angular radius
        (:func:`shadow_directions`); 1 ray: a hard shadow.

    Returns
    -------
    (P,) float32
        The fraction of a point's shadow rays that reach the light: 1 where
        the light reaches the surface point (and on misses), 0 where the mesh
        occludes it, in between on a soft shadow's edge.
    """
    idx = np.flatnonzero(hits.prim_id >= 0)
    visibility = np.ones(len(hits.prim_id), np.float32)
    if idx.size == 0:
        return visibility
    tri = np.asarray(triangles)[hits.prim_id[idx]]
    u, w = hits.bary[idx, :1], hits.bary[idx, 1:]
    pts = (1.0 - u - w) * vertices[tri[:, 0]] + u * vertices[tri[:, 1]] + w * vertices[tri[:, 2]]
    r = euler_rotation(pose.roll, pose.yaw, pose.pitch)
    dirs = shadow_directions(direction, rays, spread_deg) @ r  # rows: r.T @ d, model frame
    lit = np.zeros(idx.size, np.float32)
    for l_model in dirs:
        # start just off the surface towards the light, so the point's own triangle is not hit
        start = (pts + 1e-4 * caster.scale * l_model).astype(np.float32)
        lit += ~caster.occluded(start, l_model.reshape(1, 3).astype(np.float32))
    visibility[idx] = lit / len(dirs)
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
