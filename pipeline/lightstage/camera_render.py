"""Ray-cast images of per-vertex values seen by a lightstage camera.

One primary ray per pixel centre (through the camera's lens distortion) and
the nearest front-facing hit (:func:`cast_pixels`, which keeps the hit
triangle, barycentric weights and depth so that callers can shade per pixel),
or directly an image of per-vertex values interpolated with the barycentric
weights (Gouraud; :func:`render_vertex_values`). Background pixels are 0.
Camera-frame ray directions depend only on the intrinsics and are cached, so
the iterative undistortion runs once per camera model.

Imports only :mod:`albedo_model` and :mod:`pipeline.texturing.cameras`.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.render.raycast import RayCaster
from pipeline.texturing.cameras import LightstageCamera

__all__ = ["PixelHits", "camera_frame_rays", "cast_pixels", "render_vertex_values"]


@lru_cache(maxsize=32)
def _rays(focal: float, pp: tuple[float, float], size: tuple[int, int],
          distortion: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    cam = LightstageCamera(rotation=np.eye(3), translation=np.zeros(3), focal_px=focal,
                           principal_px=np.array(pp), image_size=size,
                           distortion=np.array(distortion))
    h, w = size
    vv, uu = np.mgrid[0:h, 0:w]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64)
    d, ok = cam.pixel_rays(uv)
    d = d.astype(np.float32)
    d.setflags(write=False)
    ok.setflags(write=False)
    return d, ok


def camera_frame_rays(camera: LightstageCamera) -> tuple[np.ndarray, np.ndarray]:
    """Return the unit ray directions of all pixel centres in the camera frame (cached).

    Returns
    -------
    directions : (H*W, 3) float32, read-only
        Row-major over the image.
    ok : (H*W,) bool, read-only
        False where the distortion could not be inverted.
    """
    return _rays(float(camera.focal_px), tuple(float(x) for x in camera.principal_px),
                 tuple(int(x) for x in camera.image_size),
                 tuple(float(x) for x in camera.distortion))


class PixelHits(NamedTuple):
    """The pixels of an image that see the mesh, and where.

    Attributes
    ----------
    pixel : (P,) int64
        Row-major indices of the pixels that hit a front face.
    corners : (P, 3) int64
        Vertex indices of the hit triangle.
    weights : (P, 3) float64
        Barycentric weights of the hit point.
    shape : (H, W)
    depth : (P,) float32 or None
        Distance from the camera centre along the ray (mesh units).
    """

    pixel: np.ndarray
    corners: np.ndarray
    weights: np.ndarray
    shape: tuple[int, int]
    depth: np.ndarray | None = None

    def interpolate(self, values: np.ndarray) -> np.ndarray:
        """(P, ...) values at the hit points from per-vertex values (n, ...)."""
        vals = np.asarray(values)
        dtype = vals.dtype if vals.dtype.kind == "f" else np.float64
        w = self.weights.astype(dtype, copy=False)
        w = w.reshape(w.shape + (1,) * (vals.ndim - 1))
        out = vals[self.corners[:, 0]] * w[:, 0]
        out += vals[self.corners[:, 1]] * w[:, 1]
        out += vals[self.corners[:, 2]] * w[:, 2]
        return out

    def image(self, pixel_values: np.ndarray) -> np.ndarray:
        """(H, W, C) float32 image with ``pixel_values`` (P, C) at the hit pixels, 0 elsewhere."""
        vals = np.asarray(pixel_values, np.float32)
        h, w = self.shape
        out = np.zeros((h * w, vals.shape[1]), np.float32)
        out[self.pixel] = vals
        return out.reshape(h, w, -1)

    def depth_edges(self, jump: float) -> np.ndarray:
        """(H, W) bool: hit pixels next to (8-neighbourhood) a miss or a depth change > ``jump``.

        Marks occlusion boundaries, where a pixel's neighbourhood shows another surface.
        """
        if self.depth is None:
            raise InputError("these hits carry no depth")
        h, w = self.shape
        depth = np.full(h * w, np.inf)
        depth[self.pixel] = self.depth
        depth = np.pad(depth.reshape(h, w), 1, constant_values=np.inf)
        centre = depth[1:-1, 1:-1]
        edge = np.zeros((h, w), bool)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dy or dx:
                    other = depth[1 + dy:h + 1 + dy, 1 + dx:w + 1 + dx]
                    with np.errstate(invalid="ignore"):
                        edge |= ~(np.abs(other - centre) <= jump)
        return edge & np.isfinite(centre)

    def coverage(self) -> np.ndarray:
        """(H, W) bool: pixels that see the mesh."""
        out = np.zeros(self.shape[0] * self.shape[1], bool)
        out[self.pixel] = True
        return out.reshape(self.shape)


def cast_pixels(camera: LightstageCamera, caster: RayCaster,
                triangles: np.ndarray) -> PixelHits:
    """Primary rays through every pixel centre; the nearest front-facing hits.

    Parameters
    ----------
    camera : LightstageCamera
        World = the frame of the caster's mesh.
    caster : RayCaster
    triangles : (m, 3) int array
        The caster's triangles.
    """
    h, w = camera.image_size
    d_cam, ok = camera_frame_rays(camera)
    d = np.ascontiguousarray(d_cam @ camera.rotation.astype(np.float32))
    origin = np.ascontiguousarray(np.broadcast_to(camera.centre.astype(np.float32), d.shape))
    hits = caster.cast(origin, d, image_shape=(h, w))
    idx = np.flatnonzero((hits.prim_id >= 0) & ok)
    corners = np.asarray(triangles, np.int64)[hits.prim_id[idx]]
    u = hits.bary[idx, 0].astype(np.float64)
    v = hits.bary[idx, 1].astype(np.float64)
    return PixelHits(idx, corners, np.stack([1.0 - u - v, u, v], axis=1), (h, w), hits.t[idx])


def render_vertex_values(camera: LightstageCamera, caster: RayCaster, triangles: np.ndarray,
                         values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Image of per-vertex values on the mesh held by ``caster``.

    Parameters
    ----------
    camera : LightstageCamera
        World frame = the frame of the caster's mesh.
    caster : RayCaster
    triangles : (m, 3) int array
        The caster's triangles.
    values : (n, C) float array
        Per-vertex values (e.g. raw radiance), linearly interpolated.

    Returns
    -------
    image : (H, W, C) float32
        0 where no front face is hit.
    coverage : (H, W) bool
    """
    vals = np.asarray(values, np.float64)
    if vals.ndim != 2:
        raise InputError(f"values must have shape (n, C), got {vals.shape}")
    hits = cast_pixels(camera, caster, triangles)
    return hits.image(hits.interpolate(vals)), hits.coverage()
