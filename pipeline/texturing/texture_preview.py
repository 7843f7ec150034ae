"""A picture to judge a stitched texture: photographs beside renders of the texture.

Each view gets a column: the photograph (cropped to the mesh, reduced by
``factor``), the stitched per-vertex colour rendered unlit through the same
camera (ambient white light, so seams show as colour steps, not shading), and
the same render tinted by the view each triangle took its gradients from
(view 1 red, 2 green, 3 blue, ...; grey where no view was valid).

Rendering casts one ray per output pixel through the calibrated camera
(distortion inverted per pixel) and interpolates the vertex colours with the
hit's barycentrics.

Imports :mod:`albedo_model` and :mod:`pipeline.texturing.cameras`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from albedo_model.render.raycast import RayCaster
from pipeline.texturing.cameras import LightstageCamera

__all__ = ["mesh_box", "reduce_image", "render_vertex_colours", "stitch_preview"]

_PALETTE = np.array([[0.9, 0.15, 0.1], [0.1, 0.75, 0.2], [0.15, 0.35, 0.95],
                     [0.9, 0.8, 0.1], [0.8, 0.2, 0.8], [0.1, 0.8, 0.8]], np.float32)
_NO_VIEW = np.array([0.5, 0.5, 0.5], np.float32)


def mesh_box(camera: LightstageCamera, vertices: np.ndarray, margin: float = 0.05
             ) -> tuple[int, int, int, int]:
    """Pixel box ``(row0, row1, col0, col1)`` (end exclusive) around the projected mesh.

    ``margin`` is a fraction of the box size added on every side; the box is
    clipped to the image.
    """
    uv = camera.project(vertices)
    uv = uv[np.isfinite(uv).all(axis=1)]
    h, w = camera.image_size
    if len(uv) == 0:
        return 0, h, 0, w
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    pad = margin * (hi - lo).max()
    c0, r0 = np.maximum(np.floor(lo - pad), 0).astype(int)
    c1, r1 = np.minimum(np.ceil(hi + pad) + 1, [w, h]).astype(int)
    if r1 <= r0 or c1 <= c0:
        return 0, h, 0, w
    return int(r0), int(r1), int(c0), int(c1)


def render_vertex_colours(camera: LightstageCamera, caster: RayCaster, triangles: np.ndarray,
                          colours: np.ndarray, *, box: tuple[int, int, int, int] | None = None
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Render per-vertex colours, unlit, through a camera.

    Parameters
    ----------
    camera : LightstageCamera
        Often ``camera.scaled(f)`` for a smaller picture.
    caster : RayCaster
        Built on the mesh (world frame).
    triangles : (m, 3) int array
    colours : (n, C) float array
    box : (row0, row1, col0, col1), optional
        Sub-window of the camera's image to render; default the whole image.

    Returns
    -------
    image : (h, w, C) float32
        0 where no triangle is hit.
    triangle : (h, w) int32
        Index of the visible triangle, -1 for background.
    """
    h, w = camera.image_size
    r0, r1, c0, c1 = (0, h, 0, w) if box is None else box
    rows, cols = np.mgrid[r0:r1, c0:c1]
    uv = np.stack([cols.ravel(), rows.ravel()], axis=1).astype(np.float64)
    dirs, ok = camera.pixel_rays(uv)
    origins = np.broadcast_to(camera.centre, dirs.shape)
    hits = caster.cast(origins, dirs, image_shape=rows.shape)
    prim = np.where(ok, hits.prim_id, -1).astype(np.int32)
    col = np.asarray(colours, np.float32)
    out = np.zeros((len(prim), col.shape[1]), np.float32)
    hit = prim >= 0
    tri = np.asarray(triangles)[prim[hit]]
    bu, bv = hits.bary[hit, 0:1], hits.bary[hit, 1:2]
    out[hit] = (1 - bu - bv) * col[tri[:, 0]] + bu * col[tri[:, 1]] + bv * col[tri[:, 2]]
    return out.reshape(*rows.shape, -1), prim.reshape(rows.shape)


def reduce_image(image: np.ndarray, factor: int, box: tuple[int, int, int, int]) -> np.ndarray:
    """Block-average of ``image`` over ``factor x factor`` pixels, rows/cols ``box`` of the result.

    Parameters
    ----------
    image : (H, W, 3) uint8, uint16 or float array (integers scaled to [0, 1])
    factor : int
    box : (row0, row1, col0, col1) in reduced pixels

    Returns
    -------
    (row1 - row0, col1 - col0, 3) float32, zero-padded beyond the image.
    """
    r0, r1, c0, c1 = box
    top = 255.0 if image.dtype == np.uint8 else 65535.0 if image.dtype == np.uint16 else 1.0
    part = image[r0 * factor:r1 * factor, c0 * factor:c1 * factor]
    out = np.zeros((r1 - r0, c1 - c0, 3), np.float32)
    hh, ww = part.shape[0] // factor, part.shape[1] // factor
    blocks = part[:hh * factor, :ww * factor].reshape(hh, factor, ww, factor, -1)
    out[:hh, :ww] = blocks.mean(axis=(1, 3), dtype=np.float32)[..., :3] / np.float32(top)
    return out


def stitch_preview(images: Sequence[np.ndarray], cameras: Sequence[LightstageCamera],
                   vertices: np.ndarray, triangles: np.ndarray, colour: np.ndarray,
                   selected_view: np.ndarray, *, factor: int = 4,
                   caster: RayCaster | None = None) -> np.ndarray:
    """Compose the comparison picture of the module notes.

    Parameters
    ----------
    images : sequence of (H, W, 3) arrays, one per camera
    cameras : sequence of LightstageCamera
    vertices : (n, 3) float array, world frame
    triangles : (m, 3) int array
    colour : (n, 3) float array
        Stitched colours, [0, 1].
    selected_view : (m,) int array, -1 for none
    factor : int
        Size reduction of the photographs and renders.
    caster : RayCaster, optional

    Returns
    -------
    (H', W', 3) float32 in [0, 1]: three rows (photo, texture, selection), one column per view.
    """
    caster = RayCaster(vertices, triangles) if caster is None else caster
    sel = np.asarray(selected_view)
    tint = np.where((sel >= 0)[:, None], _PALETTE[np.maximum(sel, 0) % len(_PALETTE)], _NO_VIEW)
    columns = []
    for image, camera in zip(images, cameras):
        small = camera.scaled(factor)
        box = mesh_box(small, vertices)
        render, prim = render_vertex_colours(small, caster, triangles, colour, box=box)
        render = np.clip(render, 0.0, 1.0)
        mix = np.where((prim >= 0)[..., None], 0.55 * render + 0.45 * tint[prim], 0.0)
        columns.append(np.concatenate([reduce_image(image, factor, box), render, mix], axis=0))
    height = max(c.shape[0] for c in columns)
    gap = np.ones((height, 4, 3), np.float32)
    padded = []
    for c in columns:
        pad = np.zeros((height - c.shape[0], c.shape[1], 3), np.float32)
        padded += [np.concatenate([c, pad], axis=0), gap]
    return np.concatenate(padded[:-1], axis=1)
