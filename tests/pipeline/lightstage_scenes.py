"""Analytic lightstage scenes for tests: spheres seen by calibrated cameras, no renderer.

Images are made pixel by pixel from exact ray-sphere intersections and a known
colour function, so sampled vertex colours have an independent ground truth.
"""

from __future__ import annotations

import numpy as np
import trimesh

from pipeline.texturing.cameras import LightstageCamera


def look_at(eye, target, up, *, focal_px: float, size: tuple[int, int],
            distortion=(0.0, 0.0, 0.0, 0.0, 0.0)) -> LightstageCamera:
    """A camera at ``eye`` looking at ``target``, image y pointing along ``-up``."""
    eye, target, up = (np.asarray(a, np.float64) for a in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    y = -(up - (up @ z) * z)
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    R = np.stack([x, y, z])
    h, w = size
    return LightstageCamera(rotation=R, translation=-R @ eye, focal_px=focal_px,
                            principal_px=np.array([(w - 1) / 2, (h - 1) / 2]),
                            image_size=(h, w), distortion=np.asarray(distortion, np.float64))


def sphere_colour(points: np.ndarray, centre, radius: float) -> np.ndarray:
    """A smooth RGB texture on a sphere: (n, 3) in [0.2, 0.8]."""
    q = (np.asarray(points, np.float64) - centre) / radius
    mix = np.array([[0.3, 0.1, 0.0], [-0.1, 0.2, 0.15], [0.05, -0.1, 0.25]])
    return 0.5 + q @ mix.T


def render_spheres(camera: LightstageCamera, spheres, colours=None) -> np.ndarray:
    """Exact image of spheres ``[(centre, radius), ...]`` through ``camera``, float64 (H, W, 3).

    The nearest sphere along each pixel's ray gives the colour
    ``colours[i](point)`` (default :func:`sphere_colour`); background is 0.
    """
    h, w = camera.image_size
    rows, cols = np.mgrid[0:h, 0:w]
    dirs, _ = camera.pixel_rays(np.stack([cols.ravel(), rows.ravel()], 1).astype(float))
    eye = camera.centre
    best_t = np.full(len(dirs), np.inf)
    image = np.zeros((len(dirs), 3))
    for i, (centre, radius) in enumerate(spheres):
        oc = eye - np.asarray(centre, float)
        b = dirs @ oc
        disc = b * b - (oc @ oc - radius * radius)
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(disc)
        hit = (disc >= 0) & (t > 0) & (t < best_t)
        points = eye + t[hit, None] * dirs[hit]
        fn = colours[i] if colours else (lambda p, c=centre, r=radius: sphere_colour(p, c, r))
        image[hit] = fn(points)
        best_t[hit] = t[hit]
    return image.reshape(h, w, 3)


def sphere_mesh(centre, radius: float, subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Icosphere vertices (on the sphere) and outward counter-clockwise triangles."""
    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(s.vertices) * radius + np.asarray(centre, float), np.asarray(s.faces)


def union(*meshes) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate (vertices, triangles) pairs into one mesh."""
    verts, tris, offset = [], [], 0
    for v, t in meshes:
        verts.append(v)
        tris.append(t + offset)
        offset += len(v)
    return np.concatenate(verts), np.concatenate(tris).astype(np.int32)


def ray_clearance(points: np.ndarray, eye: np.ndarray, centre, radius: float) -> np.ndarray:
    """Distance between the segment point -> eye and a sphere's surface (negative if it cuts it)."""
    p = np.asarray(points, float)
    d = eye - p
    length = np.linalg.norm(d, axis=1)
    u = d / length[:, None]
    s = np.clip(np.einsum("ij,ij->i", np.asarray(centre, float) - p, u), 0, length)
    closest = p + s[:, None] * u
    return np.linalg.norm(closest - np.asarray(centre, float), axis=1) - radius
