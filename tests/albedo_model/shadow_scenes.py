"""A sphere with a nose under a side light: a scene whose cast shadows are easy to check.

The nose (a Gaussian ridge on the front, +z) casts a real shadow on a cheek
besides the attached shadow of the far side. Used by the cast-shadow tests and
the render command's.
"""

from __future__ import annotations

import functools

import numpy as np
import trimesh
from renderer_scenes import scene

from albedo_model.camera import euler_rotation
from albedo_model.model import MorphableModel
from albedo_model.params import DirectionalLight, SHLight
from albedo_model.pca import PCAPart

SIZE = (120, 120)
RADIUS = 60.0
NOSE_HEIGHT = 0.45  # of the radius


@functools.lru_cache(maxsize=1)
def nosed_model(k: int = 3) -> MorphableModel:
    """Return a sphere-with-a-nose morphable model (2562 vertices, outward triangles).

    The first shape component lengthens the nose (+10 mm at the tip per unit
    coefficient); the others are small random displacements.
    """
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=RADIUS)
    u = np.asarray(mesh.vertices) / RADIUS
    profile = np.exp(-(u[:, 0] / 0.2) ** 2 - ((u[:, 1] + 0.05) / 0.35) ** 2) * (u[:, 2] > 0)
    v = RADIUS * u * (1.0 + NOSE_HEIGHT * profile)[:, None]
    n3 = 3 * len(v)
    rng = np.random.default_rng(0)
    nose = (RADIUS * u * profile[:, None]).ravel()  # displacement of a nose one radius long
    q, _ = np.linalg.qr(np.column_stack([nose, rng.standard_normal((n3, k - 1))]))
    q[:, 0] *= np.sign(q[:, 0] @ nose)
    shape_sd = np.r_[10.0 * np.linalg.norm(nose) / RADIUS, np.full(k - 1, 2.0)]

    def part(mean, variance):
        basis, _ = np.linalg.qr(rng.standard_normal((n3, k)))
        return PCAPart(mean, basis, np.full(k, variance))

    colour = 0.45 + 0.15 * np.sin(v / 17.0)
    return MorphableModel(v, np.asarray(mesh.faces), PCAPart(v.ravel(), q, shape_sd ** 2),
                          part(colour.ravel(), 0.05), specular=part(np.full(n3, 0.3), 0.01))


def side_light(azimuth_deg: float, elevation_deg: float, diffuse: float = 0.6) -> DirectionalLight:
    """Return a white directional light without ambient and specular terms."""
    return DirectionalLight.from_angles(np.radians(azimuth_deg), np.radians(elevation_deg),
                                        (diffuse,) * 3, specular=(0.0, 0.0, 0.0))


def lit_scene(yaw_deg: float, azimuth_deg: float, elevation_deg: float):
    """Return the 120 x 120 scene of :func:`nosed_model`: dim frontal SH light, a side light."""
    p = scene(size=SIZE, yaw=np.radians(yaw_deg), pitch=-0.1, sh=SHLight.frontal(0.3, 0.1))
    return p._replace(directional_light=side_light(azimuth_deg, elevation_deg))


def reference_occlusion(state, triangles, directions):
    """Occlusion of light directions at every face pixel of ``state``, cast with trimesh.

    Parameters
    ----------
    state : RenderState
    triangles : (m, 3) int array
    directions : (D, 3) float
        Directions towards the light, world frame (any length).

    Returns
    -------
    face : (F,) int
        Row-major image indices of the pixels whose primary ray hit the mesh.
    occluded : (D, F) bool
        The mesh lies between the pixel's surface point and the light, per direction.
    n_dot_l : (F,) float
        Flat normal of the hit triangle dotted with the first unit direction (model frame).
    points : (F, 3) float
        The surface points (model frame).
    """
    p = state.params
    prim = np.asarray(state.hits.prim_id)
    face = np.flatnonzero(prim >= 0)
    vertices = np.asarray(state.shape, np.float64).reshape(-1, 3)
    tri = np.asarray(triangles)[prim[face]]
    bary = np.asarray(state.hits.bary, np.float64)[face]
    u, v = bary[:, :1], bary[:, 1:2]
    points = ((1.0 - u - v) * vertices[tri[:, 0]] + u * vertices[tri[:, 1]]
              + v * vertices[tri[:, 2]])
    rotation = euler_rotation(p.pose.roll, p.pose.yaw, p.pose.pitch)
    mesh = trimesh.Trimesh(vertices, triangles, process=False)
    occluded, n_dot_l = [], None
    for d_world in np.asarray(directions, np.float64).reshape(-1, 3):
        light = rotation.T @ (d_world / np.linalg.norm(d_world))
        origins = points + 1e-5 * mesh.scale * light  # off the point's own triangle
        occluded.append(np.asarray(
            mesh.ray.intersects_any(origins, np.tile(light, (len(face), 1))), bool))
        if n_dot_l is None:
            n_dot_l = mesh.face_normals[prim[face]] @ light
    return face, np.array(occluded), n_dot_l, points
