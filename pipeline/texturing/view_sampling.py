"""Per-view sampling of photographs onto a registered mesh (AlbedoMM, Sec. 3.3).

For each view and vertex: the bilinearly interpolated image colour at the
vertex's projection, and a weight

    w = max(0, n . (c - X) / |c - X|)      if the vertex is valid, else 0,

with ``n`` the unit vertex normal and ``c`` the camera centre. A vertex is
valid when it projects inside the image, faces the camera (``w > 0``), has a
free line of sight to the camera (occlusion rays,
:func:`albedo_model.render.raycast.visible_points`) and lies at least
``boundary_distance_px`` from the occluding boundary: the
distance transform of the hole-filled silhouette of the projected mesh, so that
background is not sampled onto the mesh. The silhouette is rasterised at a
reduced resolution (``mask_scale``; its distances are accurate to about that
many pixels), which is ample against a 100-pixel threshold.

This module imports :mod:`albedo_model`, :mod:`pipeline.texturing.cameras` and
:mod:`pipeline.texturing.triangle_coverage`.
"""

from __future__ import annotations

import time
from collections.abc import MutableMapping, Sequence
from typing import NamedTuple

import numpy as np
from scipy import ndimage

from albedo_model.errors import InputError
from albedo_model.model import vertex_normals
from albedo_model.render.raycast import RayCaster, visible_points
from pipeline.texturing.cameras import LightstageCamera
from pipeline.texturing.triangle_coverage import coverage_mask

__all__ = ["ViewSamples", "bilinear_sample", "sample_view", "sample_views", "silhouette_distance"]


class ViewSamples(NamedTuple):
    """The samples of one view on the mesh vertices.

    Attributes
    ----------
    colour : (n, 3) float32
        Bilinear image samples on the image's [0, 1] scale; 0 where the vertex
        projects outside the image.
    weight : (n,) float32
        Cosine between normal and view direction on valid vertices, 0 elsewhere.
    valid : (n,) bool
        ``weight > 0``: inside, facing, unoccluded and away from the silhouette.
    """

    colour: np.ndarray
    weight: np.ndarray
    valid: np.ndarray


class _Clock:
    """Adds the seconds since the last lap to ``timings[name]`` (no-op without a dict)."""

    def __init__(self, timings: MutableMapping[str, float] | None):
        self.timings, self.t = timings, time.perf_counter()

    def lap(self, name: str) -> None:
        if self.timings is not None:
            now = time.perf_counter()
            self.timings[name] = self.timings.get(name, 0.0) + now - self.t
            self.t = now


def _unit_scale(image: np.ndarray) -> float:
    if image.dtype == np.uint8:
        return 1.0 / 255.0
    if image.dtype == np.uint16:
        return 1.0 / 65535.0
    if image.dtype.kind == "f":
        return 1.0
    raise InputError(f"unsupported image dtype {image.dtype}")


def bilinear_sample(image: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear interpolation of an image at continuous pixel positions.

    Parameters
    ----------
    image : (H, W) or (H, W, C) uint8, uint16 or float array
        Integer images are scaled to [0, 1] (value/255, value/65535).
    uv : (n, 2) float array
        ``(u, v)`` 0-based pixel coordinates (column, row; pixel centres at integers).

    Returns
    -------
    values : (n, C) float32
        0 for positions outside ``[0, W-1] x [0, H-1]`` (or non-finite).
    inside : (n,) bool
    """
    img = np.asarray(image)
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3:
        raise InputError(f"image must have shape (H, W) or (H, W, C), got {image.shape}")
    h, w = img.shape[:2]
    uv = np.asarray(uv, np.float64)
    u, v = uv[:, 0], uv[:, 1]
    with np.errstate(invalid="ignore"):
        inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
    u = np.where(inside, u, 0.0)
    v = np.where(inside, v, 0.0)
    u0 = np.clip(np.floor(u).astype(np.int64), 0, max(w - 2, 0))
    v0 = np.clip(np.floor(v).astype(np.int64), 0, max(h - 2, 0))
    u1, v1 = np.minimum(u0 + 1, w - 1), np.minimum(v0 + 1, h - 1)
    fu = (u - u0).astype(np.float32)[:, None]
    fv = (v - v0).astype(np.float32)[:, None]
    top = img[v0, u0].astype(np.float32) * (1 - fu) + img[v0, u1].astype(np.float32) * fu
    bottom = img[v1, u0].astype(np.float32) * (1 - fu) + img[v1, u1].astype(np.float32) * fu
    values = (top * (1 - fv) + bottom * fv) * np.float32(_unit_scale(img))
    values[~inside] = 0.0
    return values, inside


def silhouette_distance(camera: LightstageCamera, vertices: np.ndarray, triangles: np.ndarray,
                        *, mask_scale: int = 4) -> tuple[np.ndarray, LightstageCamera]:
    """Distance from each pixel to the outside of the mesh's hole-filled silhouette.

    Parameters
    ----------
    camera : LightstageCamera
    vertices : (n, 3) float array, world frame
    triangles : (m, 3) int array
    mask_scale : int
        The silhouette is rasterised on a grid ``mask_scale`` times coarser.

    Returns
    -------
    distance : (H', W') float32
        In full-resolution pixels; 0 outside the silhouette.
    grid_camera : LightstageCamera
        ``camera.scaled(mask_scale)``: projects onto the grid of ``distance``.
    """
    if int(mask_scale) < 1:
        raise InputError(f"mask_scale must be a positive integer, got {mask_scale}")
    small = camera.scaled(int(mask_scale))
    uv = small.project(vertices)
    mask = coverage_mask(uv[np.asarray(triangles)], small.image_size)
    mask = ndimage.binary_fill_holes(mask)
    dist = ndimage.distance_transform_edt(mask).astype(np.float32) * np.float32(mask_scale)
    return dist, small


def sample_view(image: np.ndarray, camera: LightstageCamera, vertices: np.ndarray,
                triangles: np.ndarray, *, normals: np.ndarray | None = None,
                caster: RayCaster | None = None, boundary_distance_px: float = 100.0,
                mask_scale: int = 4, timings: MutableMapping[str, float] | None = None
                ) -> ViewSamples:
    """Sample one photograph onto the mesh (see the module notes for the rules).

    Parameters
    ----------
    image : (H, W, 3) uint8, uint16 or float array
        Must match ``camera.image_size``.
    camera : LightstageCamera
    vertices : (n, 3) float array, world frame
    triangles : (m, 3) int array, counter-clockwise seen from outside
    normals : (n, 3) float array, optional
        Unit vertex normals; default :func:`albedo_model.model.vertex_normals`.
    caster : RayCaster, optional
        Built on ``vertices, triangles`` (pass one to share it between views).
    boundary_distance_px : float
        Vertices closer than this to the silhouette (full-resolution pixels) are invalid.
    mask_scale : int
        Resolution reduction of the silhouette raster.
    timings : dict, optional
        Seconds spent are added under "sampling", "silhouette" and "visibility".

    Returns
    -------
    ViewSamples
    """
    clock = _Clock(timings)
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3:
        raise InputError(f"image must have shape (H, W, 3), got {img.shape}")
    if img.shape[:2] != tuple(camera.image_size):
        raise InputError(f"image is {img.shape[1]}x{img.shape[0]} pixels but the camera expects "
                         f"{camera.image_size[1]}x{camera.image_size[0]}")
    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles)
    nrm = vertex_normals(v, tri) if normals is None else np.asarray(normals, np.float64)
    caster = RayCaster(v, tri) if caster is None else caster
    uv = camera.project(v)
    colour, inside = bilinear_sample(img, uv)
    to_cam = camera.centre - v
    cosine = np.einsum("ij,ij->i", nrm, to_cam) / np.linalg.norm(to_cam, axis=1)
    cand = np.flatnonzero(inside & (cosine > 0))
    clock.lap("sampling")
    if boundary_distance_px > 0 and cand.size:
        dist, small = silhouette_distance(camera, v, tri, mask_scale=mask_scale)
        d, _ = bilinear_sample(dist, small.project(v[cand]))
        cand = cand[d[:, 0] >= boundary_distance_px]
    clock.lap("silhouette")
    if cand.size:
        cand = cand[visible_points(v[cand], camera.centre, caster)]
    clock.lap("visibility")
    valid = np.zeros(len(v), bool)
    valid[cand] = True
    weight = np.where(valid, cosine, 0.0).astype(np.float32)
    return ViewSamples(colour, weight, valid)


def sample_views(images: Sequence[np.ndarray], cameras: Sequence[LightstageCamera],
                 vertices: np.ndarray, triangles: np.ndarray, *,
                 boundary_distance_px: float = 100.0, mask_scale: int = 4,
                 caster: RayCaster | None = None,
                 timings: MutableMapping[str, float] | None = None) -> list[ViewSamples]:
    """:func:`sample_view` for every view, sharing normals and the ray caster.

    Parameters
    ----------
    images : sequence of (H, W, 3) arrays, one per camera
    cameras : sequence of LightstageCamera
    vertices : (n, 3) float array, world frame
    triangles : (m, 3) int array
    boundary_distance_px, mask_scale, timings : see :func:`sample_view`
    caster : RayCaster, optional

    Returns
    -------
    list of ViewSamples, one per view
    """
    if len(images) != len(cameras):
        raise InputError(f"{len(images)} images but {len(cameras)} cameras")
    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles)
    nrm = vertex_normals(v, tri)
    caster = RayCaster(v, tri) if caster is None else caster
    return [sample_view(im, cam, v, tri, normals=nrm, caster=caster,
                        boundary_distance_px=boundary_distance_px, mask_scale=mask_scale,
                        timings=timings)
            for im, cam in zip(images, cameras)]
