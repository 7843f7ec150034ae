"""Brute-force z-buffer rasteriser: an independent reference for the ray caster.

Written from the scalismo conventions (``reference-sampler.md`` §1-2) without
using :mod:`albedo_model.camera`: its own Euler rotations and projection
formula, triangles rasterised one by one at integer pixel centres (pixel (i, j)
is the point (i, j)), edge-function inside tests that include the edges,
perspective-correct barycentrics, nearest eye depth wins, back faces culled when
``n . (a - eye) > 0`` (orthographic: ``n . (0, 0, -1) > 0``, the view
direction, where scalismo would still use the eye position). Slow (Python loop
over triangles); for small meshes only.
"""

from __future__ import annotations

import numpy as np


def _rot(roll: float, yaw: float, pitch: float) -> np.ndarray:
    c, s = np.cos, np.sin
    rz = np.array([[c(roll), -s(roll), 0], [s(roll), c(roll), 0], [0, 0, 1]])
    ry = np.array([[c(yaw), 0, s(yaw)], [0, 1, 0], [-s(yaw), 0, c(yaw)]])
    rx = np.array([[1, 0, 0], [0, c(pitch), -s(pitch)], [0, s(pitch), c(pitch)]])
    return rz @ ry @ rx


def eye_points(vertices, pose, view) -> np.ndarray:
    """Model-frame vertices to eye coordinates, (n, 3) float64."""
    world = pose.scaling * np.asarray(vertices, float) @ _rot(pose.roll, pose.yaw, pose.pitch).T
    world = world + np.asarray(pose.translation, float)
    rv = _rot(view.roll, view.yaw, view.pitch)
    return (world - np.asarray(view.translation, float)) @ rv  # rv^T (p - t), row form


def screen_points(points_eye, camera, image_size) -> np.ndarray:
    """Eye points to (u, v) pixels with the scalismo formula, (n, 2) float64."""
    w, h = image_size.width, image_size.height
    f = camera.focal_length
    sx, sy = camera.sensor_size
    ppx, ppy = camera.principal_point
    d = -points_eye[:, 2] if not camera.orthographic else np.full(len(points_eye), camera.near)
    u = w / 2 * (1 + ppx) + (w * f / sx) * points_eye[:, 0] / d
    v = h / 2 * (1 - ppy) - (h * f / sy) * points_eye[:, 1] / d
    return np.stack([u, v], 1)


def render_zbuffer(vertices, triangles, pose, view, camera, image_size, *, cull: bool = True):
    """Rasterise a mesh.

    Returns
    -------
    prim : (H, W) int64, triangle index or -1
    bary : (H, W, 2) float64, perspective-correct (u, v) weights of vertices b and c
    depth : (H, W) float64, eye distance ``-z`` of the visible surface (inf if none)
    """
    w, h = image_size.width, image_size.height
    pe = eye_points(vertices, pose, view)
    px = screen_points(pe, camera, image_size)
    dep = -pe[:, 2]
    prim = np.full((h, w), -1, np.int64)
    bary = np.zeros((h, w, 2))
    zbuf = np.full((h, w), np.inf)
    for k, (ia, ib, ic) in enumerate(np.asarray(triangles)):
        a, b, c = pe[ia], pe[ib], pe[ic]
        normal = np.cross(b - a, c - a)
        # eye at the origin; orthographic cameras view along -z everywhere
        if cull and np.dot(normal, (0.0, 0.0, -1.0) if camera.orthographic else a) > 0:
            continue
        da, db, dc = dep[ia], dep[ib], dep[ic]
        if min(da, db, dc) <= 0:
            continue
        pa, pb, pc = px[ia], px[ib], px[ic]
        area = (pb[0] - pa[0]) * (pc[1] - pa[1]) - (pb[1] - pa[1]) * (pc[0] - pa[0])
        if area == 0:
            continue
        lo = np.floor(np.minimum(np.minimum(pa, pb), pc)).astype(int)
        hi = np.ceil(np.maximum(np.maximum(pa, pb), pc)).astype(int)
        x0, y0 = max(lo[0], 0), max(lo[1], 0)
        x1, y1 = min(hi[0], w - 1), min(hi[1], h - 1)
        if x0 > x1 or y0 > y1:
            continue
        ys, xs = np.mgrid[y0:y1 + 1, x0:x1 + 1].astype(float)
        # edge functions: weight of the vertex opposite each edge, times the area
        wa = (pc[0] - pb[0]) * (ys - pb[1]) - (pc[1] - pb[1]) * (xs - pb[0])
        wb = (pa[0] - pc[0]) * (ys - pc[1]) - (pa[1] - pc[1]) * (xs - pc[0])
        wc = (pb[0] - pa[0]) * (ys - pa[1]) - (pb[1] - pa[1]) * (xs - pa[0])
        la, lb, lc = wa / area, wb / area, wc / area
        inside = (la >= 0) & (lb >= 0) & (lc >= 0)
        if not inside.any():
            continue
        if camera.orthographic:
            ga, gb, gc = la, lb, lc
            z = ga * da + gb * db + gc * dc
        else:
            qa, qb, qc = la / da, lb / db, lc / dc
            s = qa + qb + qc
            ga, gb, gc = qa / s, qb / s, qc / s
            z = 1.0 / s
        sub = zbuf[y0:y1 + 1, x0:x1 + 1]
        take = inside & (z < sub) & (z >= camera.near) & (z <= camera.far)
        sub[take] = z[take]
        prim[y0:y1 + 1, x0:x1 + 1][take] = k
        bary[y0:y1 + 1, x0:x1 + 1, 0][take] = gb[take]
        bary[y0:y1 + 1, x0:x1 + 1, 1][take] = gc[take]
    return prim, bary, zbuf
