"""Per-vertex values as pictures: interpolated over a rendered view, and the frontal view.

A render state knows, for every pixel, the hit triangle's corner vertices and
barycentric weights (:class:`albedo_model.shading.interpolation.PixelHits`). Any
per-vertex quantity (posterior mean albedo, its standard deviation) is then a
picture of that view by the same interpolation the renderer applies to albedo.
:func:`std_maps` chooses the per-vertex standard deviations an uncertainty
figure shows: the coefficient-only one, and the posterior predictive one when
the model has a residual variance.

This module imports only :mod:`albedo_model.model` and :mod:`albedo_model.params`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.model import MorphableModel
from albedo_model.params import Pose, RenderParameter, View, default_square, fit_to_image_size

__all__ = ["vertex_image", "frontal_params", "encode_display", "std_maps"]


def vertex_image(state, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Interpolate per-vertex values over the pixels of a render state.

    Parameters
    ----------
    state : albedo_model.render.renderer.RenderState
    values : (n,) or (n, k) float
        One value (or k) per model vertex.

    Returns
    -------
    image : (H, W) or (H, W, k) float32
        Barycentric interpolation at every pixel's hit; 0 where no ray hit.
    mask : (H, W) bool
        Pixels whose ray hit the mesh.
    """
    vals = np.asarray(values, np.float32)
    flat = vals.reshape(vals.shape[0], -1)
    hits = state.pixel_hits  # of the state's pixel set: expanded to the image below
    mask = state.full(hits.mask, False)
    out = np.zeros((mask.shape[0], flat.shape[1]), np.float32)
    for corner, weight in zip(hits.corner, hits.weight):
        out += state.full(weight)[:, None] * flat[state.full(corner, 0)]
    out[~mask] = 0.0
    w, h = state.params.image_size
    shape = (h, w) if vals.ndim == 1 else (h, w, flat.shape[1])
    return out.reshape(shape), mask.reshape(h, w)


def frontal_params(params: RenderParameter, model: MorphableModel, *,
                   size: tuple[int, int] | None = None, margin: float = 0.22) -> RenderParameter:
    """Return a frontal view of the instance in ``params``, framing the face.

    The instance (shape and expression coefficients of ``params``) faces the
    camera (zero rotation) under the default camera fitted to ``size`` (default:
    ``params``' image size); the camera distance frames the bounding box of the
    model's landmarks (the whole mesh without landmarks) with ``margin`` on every
    side along the shorter image side. Light, colour transform and specular
    exponent stay those of ``params``, so a renderer reuses its compiled stages
    (the maps only need the view's ray hits).
    """
    m = params.momo
    verts = model.shape_instance(np.asarray(m.shape), np.asarray(m.expression)
                                 if model.expression is not None else None)
    ids = list(model.landmark_vertices.values())
    pts = verts[ids] if len(ids) >= 3 else verts
    lo, hi = pts.min(0), pts.max(0)
    centre = 0.5 * (lo + hi)
    extent = float(max(hi[0] - lo[0], hi[1] - lo[1])) * (1.0 + 2.0 * margin)
    w, h = size if size is not None else params.image_size
    base = fit_to_image_size(default_square(), int(w), int(h))
    cam = base.camera
    # the shorter sensor side spans ``extent`` at distance d: d = f * extent / sensor
    distance = cam.focal_length * extent / min(cam.sensor_size)
    pose = Pose(scaling=1.0, translation=(-float(centre[0]), -float(centre[1]),
                                          -(distance + float(hi[2]))), roll=0.0, yaw=0.0, pitch=0.0)
    return base._replace(pose=pose, view=View(), environment_map=params.environment_map,
                         directional_light=params.directional_light, momo=m,
                         color_transform=params.color_transform,
                         specular_exponent=params.specular_exponent)


def encode_display(linear: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    """Clip linear values to [0, 1] and apply the pure power ``1 / gamma`` (display encoding)."""
    return np.clip(np.asarray(linear, np.float64), 0.0, 1.0) ** (1.0 / gamma)


def std_maps(part) -> list[tuple[str, np.ndarray]]:
    """Per-vertex standard deviations to picture for one albedo part, mean over R, G, B.

    Parameters
    ----------
    part : mcmcfit.outputs.posterior.AlbedoPosterior

    Returns
    -------
    list of (label, (n,) float64)
        ``("coefficients only", ...)`` always; then ``("predictive (+ model
        residual)", ...)`` when ``part.predictive``.
    """
    maps = [("coefficients only", np.asarray(part.coefficient_only().std, np.float64).mean(1))]
    if part.predictive:
        maps.append(("predictive (+ out-of-span variance)", np.asarray(part.std, np.float64).mean(1)))
    return maps
