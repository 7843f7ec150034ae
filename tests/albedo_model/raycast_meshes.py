"""Meshes, poses and cameras of the ray-caster tests (test_raycast, test_raycast_refit).

A closed icosphere, a bumpy sphere, an open shell (like a face mask), and the
poses and cameras they are seen with.

This module imports only :mod:`albedo_model.params`.
"""

from __future__ import annotations

import numpy as np
import trimesh

from albedo_model.params import ImageSize, Pose, default_square, fit_to_image_size


def icosphere():
    """Return a closed icosphere of radius 100 (vertices, faces)."""
    m = trimesh.creation.icosphere(3, radius=100.0)
    return np.asarray(m.vertices), np.asarray(m.faces)


def bumpy_sphere(subdiv=4):
    """Return a closed sphere of radius about 100 with sinusoidal bumps (vertices, faces)."""
    m = trimesh.creation.icosphere(subdiv, radius=1.0)
    v = np.asarray(m.vertices)
    th, ph = np.arccos(np.clip(v[:, 2], -1, 1)), np.arctan2(v[:, 1], v[:, 0])
    return v * (100 * (1 + 0.15 * np.sin(5 * th) * np.sin(4 * ph)))[:, None], np.asarray(m.faces)


def open_shell():
    """Front half of a bumpy ellipsoid: an open mesh like a face mask."""
    v, f = bumpy_sphere(3)
    keep = v[f].mean(1)[:, 2] > 0
    v = v / 100 * np.array([80.0, 100.0, 60.0])
    return v, f[keep]


def scene(size, pp=(0.0, 0.0), ortho=False):
    """Return the default camera fitted to ``size``: principal point ``pp``, orthographic or not."""
    cam_ = fit_to_image_size(default_square(), size.width, size.height).camera
    cam_ = cam_._replace(principal_point=pp, orthographic=ortho)
    return cam_._replace(near=800.0) if ortho else cam_


POSES = {
    # slightly off-centre so that pixel rays do not run exactly along mesh edges
    "frontal": (Pose(translation=(0.37, -0.21, -1000.0)), ImageSize(96, 96), (0.0, 0.0), False),
    "random": (Pose(scaling=1.3, translation=(20, -30, -900), roll=0.3, yaw=0.8, pitch=-0.4),
               ImageSize(120, 80), (0.1, -0.2), False),
    "behind": (Pose(translation=(0, 0, -1000), yaw=2.6, pitch=0.3), ImageSize(80, 110),
               (0.0, 0.0), False),
    "ortho": (Pose(scaling=0.9, yaw=-1.2), ImageSize(90, 90), (0.05, 0.05), True),
}


MESHES = {"icosphere": icosphere, "bumpy": bumpy_sphere, "open": open_shell}
