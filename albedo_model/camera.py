"""Camera and pose geometry: rigid transforms, projection to pixels, camera rays.

Conventions are scalismo-faces' (``reference-sampler.md`` §1):

* model -> world: ``p_w = t + Rz(roll) Ry(yaw) Rx(pitch) (s p)`` (:class:`Pose`);
* world -> eye: the inverse of ``T Rz Ry Rx`` of the :class:`View`;
* the camera looks down -z; for eye coordinates (x, y, z), z < 0,
  ``u = W/2 (1 + pp_x) + (W f / s_x) x / (-z)`` and
  ``v = H/2 (1 - pp_y) - (H f / s_y) y / (-z)`` with the principal point in NDC;
  orthographic mode replaces ``-z`` by the near distance ``n``;
* pixel (i, j) is the continuous point (i, j): x right, y down, no +0.5;
* depth is OpenGL NDC z mapped to [0, 1] (near -> 0, far -> 1).

Camera rays are returned in the **model frame**, so that a pose or camera change
moves only the rays and never the mesh (no BVH work). Their origins lie on the
near plane and their directions have eye-frame z component -1: the ray
parameter of a hit is therefore ``t = depth_eye - near`` in both perspective and
orthographic mode, and the far plane is at ``t = far - near``. Starting on the
near plane clips geometry per pixel as the [0, 1] depth range of a z-buffer does.

Everything here is plain numpy (float64 transforms, float32 rays). This module
imports only :mod:`albedo_model.params`.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from albedo_model.params import Camera, ImageSize, Pose, View

__all__ = [
    "euler_rotation", "world_from_model", "eye_from_world", "eye_from_model",
    "model_from_eye", "to_eye", "pixel_scale", "principal_point_px", "project_eye", "project",
    "ndc_depth", "eye_depth", "camera_rays", "eye_position_model", "towards_camera_model",
    "unproject", "pixel_window",
]


def euler_rotation(roll: float, yaw: float, pitch: float) -> np.ndarray:
    """Rotation ``Rz(roll) Ry(yaw) Rx(pitch)`` (pitch applied first).

    Parameters
    ----------
    roll, yaw, pitch : float
        Angles in radians about z, y and x (right-handed, counter-clockwise).

    Returns
    -------
    (3, 3) float64 rotation matrix.
    """
    cr, sr = np.cos(roll), np.sin(roll)
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    rz = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    return rz @ ry @ rx


def world_from_model(pose: Pose) -> tuple[np.ndarray, np.ndarray, float]:
    """Model-to-world similarity ``p_w = s R p + t``.

    Returns
    -------
    R : (3, 3) float64
    t : (3,) float64, mm
    s : float
    """
    r = euler_rotation(pose.roll, pose.yaw, pose.pitch)
    return r, np.asarray(pose.translation, np.float64), float(pose.scaling)


def eye_from_world(view: View) -> tuple[np.ndarray, np.ndarray]:
    """World-to-eye rigid transform ``p_e = R p_w + t`` (inverse of the view's ``T Rz Ry Rx``).

    Returns
    -------
    R : (3, 3) float64
    t : (3,) float64
    """
    rv = euler_rotation(view.roll, view.yaw, view.pitch)
    r = rv.T
    return r, -r @ np.asarray(view.translation, np.float64)


def eye_from_model(pose: Pose, view: View) -> tuple[np.ndarray, np.ndarray, float]:
    """Model-to-eye similarity ``p_e = s R p + t`` (pose, then view).

    Returns
    -------
    R : (3, 3) float64 rotation
    t : (3,) float64
    s : float, the pose scaling
    """
    rp, tp, s = world_from_model(pose)
    rv, tv = eye_from_world(view)
    return rv @ rp, rv @ tp + tv, s


def model_from_eye(pose: Pose, view: View) -> tuple[np.ndarray, np.ndarray, float]:
    """Eye-to-model similarity ``p = (R p_e + t) / s``, the inverse of :func:`eye_from_model`.

    Returns
    -------
    R : (3, 3) float64 rotation
    t : (3,) float64
    s : float, the pose scaling (divide by it)
    """
    r, t, s = eye_from_model(pose, view)
    return r.T, -r.T @ t, s


def to_eye(points_model: np.ndarray, pose: Pose, view: View) -> np.ndarray:
    """Model-frame points to eye coordinates.

    Parameters
    ----------
    points_model : (n, 3) float array, model frame (mm)

    Returns
    -------
    (n, 3) float64, eye frame (camera looks down -z)
    """
    r, t, s = eye_from_model(pose, view)
    return s * (np.asarray(points_model, np.float64) @ r.T) + t


def pixel_scale(camera: Camera, image_size: ImageSize) -> tuple[float, float]:
    """Focal lengths in pixels ``(W f / s_x, H f / s_y)``."""
    return (
        image_size.width * camera.focal_length / camera.sensor_size[0],
        image_size.height * camera.focal_length / camera.sensor_size[1],
    )


def principal_point_px(camera: Camera, image_size: ImageSize) -> tuple[float, float]:
    """Principal point in pixels ``(W/2 (1 + pp_x), H/2 (1 - pp_y))`` (y down)."""
    return (
        0.5 * image_size.width * (1.0 + camera.principal_point[0]),
        0.5 * image_size.height * (1.0 - camera.principal_point[1]),
    )


def ndc_depth(depth_eye: np.ndarray, camera: Camera) -> np.ndarray:
    """Window depth in [0, 1] from the positive eye distance ``d = -z``.

    Perspective: NDC ``z = (f + n) / (f - n) - 2 f n / ((f - n) d)``; orthographic:
    ``z = (2 d - f - n) / (f - n)``; window depth is ``(z + 1) / 2``.
    """
    d = np.asarray(depth_eye, np.float64)
    n, f = float(camera.near), float(camera.far)
    if camera.orthographic:
        z = (2.0 * d - f - n) / (f - n)
    else:
        with np.errstate(divide="ignore"):
            z = (f + n) / (f - n) - 2.0 * f * n / ((f - n) * d)
    return 0.5 * (z + 1.0)


def eye_depth(window_depth: np.ndarray, camera: Camera) -> np.ndarray:
    """Inverse of :func:`ndc_depth`: the positive eye distance ``-z`` of a window depth."""
    z = 2.0 * np.asarray(window_depth, np.float64) - 1.0
    n, f = float(camera.near), float(camera.far)
    if camera.orthographic:
        return 0.5 * (z * (f - n) + f + n)
    return 2.0 * f * n / ((f + n) - z * (f - n))


def project_eye(points_eye: np.ndarray, camera: Camera,
                image_size: ImageSize) -> tuple[np.ndarray, np.ndarray]:
    """Eye-frame points to pixels and window depth (the scalismo formula).

    Parameters
    ----------
    points_eye : (n, 3) float array, eye frame

    Returns
    -------
    pixels : (n, 2) float64, (u, v) = (x right, y down); pixel (i, j) is the point (i, j)
    depth : (n,) float64, window depth in [0, 1] for points between near and far
    """
    p = np.asarray(points_eye, np.float64)
    fx, fy = pixel_scale(camera, image_size)
    cx, cy = principal_point_px(camera, image_size)
    d = -p[:, 2]
    if camera.orthographic:
        denom = np.full_like(d, float(camera.near))
    else:
        denom = d
    with np.errstate(divide="ignore", invalid="ignore"):
        pixels = np.stack([cx + fx * p[:, 0] / denom, cy - fy * p[:, 1] / denom], axis=1)
    return pixels, ndc_depth(d, camera)


def project(points_model: np.ndarray, pose: Pose, view: View, camera: Camera,
            image_size: ImageSize) -> tuple[np.ndarray, np.ndarray]:
    """Model-frame points to pixels and window depth.

    Parameters
    ----------
    points_model : (n, 3) float array, model frame (mm)

    Returns
    -------
    pixels : (n, 2) float64, (u, v) pixel coordinates (x right, y down, no +0.5)
    depth : (n,) float64, OpenGL window depth in [0, 1] (smaller is nearer)
    """
    return project_eye(to_eye(points_model, pose, view), camera, image_size)


def pixel_window(bounds: np.ndarray, camera: Camera, image_size: ImageSize, pose: Pose,
                 view: View, margin: int = 1) -> tuple[int, int, int, int] | None:
    """Return the pixels whose rays can meet a model-frame box: rows ``y0:y1``, columns ``x0:x1``.

    Parameters
    ----------
    bounds : (2, 3) float array
        Corners ``(min, max)`` of an axis-aligned box in the model frame (e.g. a
        mesh's bounds).
    camera, image_size, pose, view
        Scene parameters.
    margin : int
        Extra pixels on each side (against rounding).

    Returns
    -------
    (y0, y1, x0, x1) or None
        Clipped to the image (possibly empty); None when part of the box lies
        at or behind the eye plane of a perspective camera, where projection
        does not bound it (cast every pixel then).

    Notes
    -----
    A box in front of the eye projects inside the bounding rectangle of its
    eight projected corners, so every pixel outside the window misses.
    """
    b = np.asarray(bounds, np.float64).reshape(2, 3)
    corners = np.where(_CORNERS, b[1], b[0])
    eye = to_eye(corners, pose, view)
    if not camera.orthographic and np.any(eye[:, 2] >= -1e-9 * max(1.0, float(camera.near))):
        return None
    px, _ = project_eye(eye, camera, image_size)
    if not np.all(np.isfinite(px)):
        return None
    u, v = px[:, 0], px[:, 1]
    w, h = int(image_size.width), int(image_size.height)
    x0 = min(max(math.floor(u.min()) - margin, 0), w)
    x1 = min(max(math.floor(u.max()) + 1 + margin, x0), w)
    y0 = min(max(math.floor(v.min()) - margin, 0), h)
    y1 = min(max(math.floor(v.max()) + 1 + margin, y0), h)
    return y0, y1, x0, x1


#: Which of (min, max) each of a box's eight corners takes per axis.
_CORNERS = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)], bool)


_RAY_BLOCK = 32768


def _eye_rays(camera: Camera, image_size: ImageSize) -> tuple[np.ndarray, np.ndarray]:
    """Homogeneous eye-frame ray origins (w=1) and directions (w=0), (H*W, 4) float32 each."""
    key = (*pixel_scale(camera, image_size), *principal_point_px(camera, image_size),
           float(camera.near), bool(camera.orthographic),
           int(image_size.width), int(image_size.height))
    return _eye_rays_cached(*key)


@lru_cache(maxsize=8)
def _eye_rays_cached(fx: float, fy: float, cx: float, cy: float, n: float, ortho: bool,
                     w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
    a = (np.arange(w, dtype=np.float64) - cx) / fx  # x / (-z) per column
    b = -(np.arange(h, dtype=np.float64) - cy) / fy  # y / (-z) per row
    org = np.empty((h, w, 4), np.float32)
    dirs = np.zeros((h, w, 4), np.float32)
    if ortho:
        org[..., 0] = n * a[None, :]
        org[..., 1] = n * b[:, None]
        dirs[..., 2] = -1.0
    else:
        dirs[..., 0] = a[None, :]
        dirs[..., 1] = b[:, None]
        dirs[..., 2] = -1.0
        org[..., :3] = n * dirs[..., :3]
    org[..., 2] = -n
    org[..., 3] = 1.0
    org, dirs = org.reshape(-1, 4), dirs.reshape(-1, 4)
    org.flags.writeable = False
    dirs.flags.writeable = False
    return org, dirs


@lru_cache(maxsize=8)
def _pixel_grid(w: int, h: int) -> np.ndarray:
    """(H*W, 3) float32 rows ``(i, j, 1)`` of the pixels, row-major (read-only)."""
    j, i = np.divmod(np.arange(w * h, dtype=np.int64), w)
    grid = np.stack([i, j, np.ones_like(i)], axis=1).astype(np.float32)
    grid.flags.writeable = False
    return grid


def camera_rays(camera: Camera, image_size: ImageSize, pose: Pose, view: View, *,
                out: tuple[np.ndarray, np.ndarray] | None = None,
                pixels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One ray per pixel, in the model frame, ready for the ray caster.

    Parameters
    ----------
    camera, image_size, pose, view
        Scene parameters.
    out : pair of (H*W, 3) float32 C-contiguous arrays, optional
        Preallocated ``(origins, directions)`` to fill (no allocation); with
        ``pixels``, (P, 3) each.
    pixels : (P,) int array, optional
        Row-major indices of the pixels whose rays to form (default all, in order).

    Returns
    -------
    origins : (H*W, 3) float32, model frame (or (P, 3): the ``pixels``' rays)
        Points on the near plane (eye z = -near).
    directions : (H*W, 3) float32, model frame
        Not normalised: the eye-frame direction has z component -1, so the ray
        parameter of a hit is ``t = depth_eye - near``; the far plane is at
        ``far - near``.

    Notes
    -----
    Pixel order is row-major: index ``j * W + i`` is pixel (x=i, y=j), sampled at
    the continuous point (i, j). Eye-frame rays are mapped by the inverse
    pose·view, ``p = R^T (p_e - t) / s`` (the pose scaling is undone too). A
    ray is affine in its pixel's coordinates, so both arrays are one
    ``[i, j, 1] @ (3, 3)`` float32 product over the cached pixel grid: a new
    focal length or principal point (every camera move) rebuilds no grid.
    """
    r, t, s = eye_from_model(pose, view)
    m = np.vstack([r / s, -(t @ r) / s])  # row vectors: p_model = p_eye @ (R / s) - t @ R / s
    (fx, fy), (cx, cy) = pixel_scale(camera, image_size), principal_point_px(camera, image_size)
    z = np.array([0.0, 0.0, 1.0])
    # the eye ray of pixel (i, j) is affine in (i, j): a = (i - cx) / fx, b = -(j - cy) / fy;
    # directions (a, b, -1), origins near (a, b, -1) (on the near plane, orthographic too)
    d_map = np.stack([m[0] / fx, -m[1] / fy, -cx / fx * m[0] + cy / fy * m[1] - m[2]])
    o_map = (float(camera.near) * d_map + np.outer(z, m[3])).astype(np.float32)
    d_map = (np.outer(z, -m[2]) if camera.orthographic else d_map).astype(np.float32)
    grid = _pixel_grid(int(image_size.width), int(image_size.height))
    if pixels is not None:
        grid = grid[pixels]
    if out is None:
        out = (np.empty((len(grid), 3), np.float32), np.empty((len(grid), 3), np.float32))
    origins, directions = out
    # blocks keep OpenBLAS single-threaded: its threaded sgemm spins and can
    # take 100x longer when the other core is busy (measured at 512x512)
    for i in range(0, len(grid), _RAY_BLOCK):
        np.matmul(grid[i:i + _RAY_BLOCK], o_map, out=origins[i:i + _RAY_BLOCK])
        np.matmul(grid[i:i + _RAY_BLOCK], d_map, out=directions[i:i + _RAY_BLOCK])
    return origins, directions


def eye_position_model(pose: Pose, view: View) -> np.ndarray:
    """Return the camera centre (eye) in the model frame, (3,) float64."""
    r, t, s = eye_from_model(pose, view)
    return -(r.T @ t) / s


def towards_camera_model(pose: Pose, view: View) -> np.ndarray:
    """Return the unit direction towards the camera (eye +z) in the model frame, (3,) float64.

    For orthographic cameras this replaces the eye position in visibility tests.
    """
    r, _, _ = eye_from_model(pose, view)
    return r[2].copy()


def unproject(pixels: np.ndarray, window_depth: np.ndarray, pose: Pose, view: View,
              camera: Camera, image_size: ImageSize) -> np.ndarray:
    """Inverse of :func:`project`: pixels and window depth back to model-frame points.

    Parameters
    ----------
    pixels : (n, 2) float array, (u, v)
    window_depth : (n,) float array in [0, 1)

    Returns
    -------
    (n, 3) float64, model frame
    """
    px = np.asarray(pixels, np.float64)
    d = eye_depth(window_depth, camera)
    fx, fy = pixel_scale(camera, image_size)
    cx, cy = principal_point_px(camera, image_size)
    scale = np.full_like(d, float(camera.near)) if camera.orthographic else d
    pe = np.stack([(px[:, 0] - cx) / fx * scale, -(px[:, 1] - cy) / fy * scale, -d], axis=1)
    r, t, s = eye_from_model(pose, view)
    return ((pe - t) @ r) / s
