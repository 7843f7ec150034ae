"""The face's size in the image: the coordinate that straightens the focal-length ridge.

An image pins how large the face appears, ``f`` times the face's size over its
distance, far more tightly than it pins the focal length ``f``, the distance
or the shape coefficients that set the size. In the coordinates ``log f``,
``log d`` and ``shape`` that constraint is a thin *curved* ridge: the face's
size is linear (not logarithmic) in the shape coefficients, the face's surface
sits ~100 mm in front of the model origin the distance is measured to, and a
sideways translation changes the depth of the face's points. A Gaussian
approximation at the mode cannot follow the curve; on the demo face the
posterior is 5.6 times wider than the Laplace approximation along that one
direction (in whitened coordinates; every other direction within 0.6-2.4) and
Gaussian moves crawl along it.

:class:`ImageScale` measures the size exactly as the image does: the RMS
distance, in pixels, of a fixed set of anchor vertices' projections from
their centroid, at unit focal length. Because a pinhole projection is linear in
``f``, the log image size is ``log f + log_radius(x)``;
:class:`~proposals.laplace.coordinates.SamplingCoordinates` uses it in place of
``log f`` (whitened, the demo posterior's widest direction drops to 2.4).

The anchors are chosen once (the vertices a fit's region pixels see at the
mode) and never change, so the coordinates are a fixed bijection.

This module imports :mod:`albedo_model` (camera, errors, model, params, scene_vector).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from albedo_model.camera import eye_from_world, euler_rotation, pixel_scale
from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import RenderParameter
from albedo_model.scene_vector import SceneLayout

__all__ = ["MAX_ANCHORS", "ImageScale", "anchor_vertices"]

#: Anchor vertices at most (a regular subset of the seen ones; the radius is a mean).
MAX_ANCHORS = 1000


def anchor_vertices(triangles: np.ndarray, seen: np.ndarray,
                    max_anchors: int = MAX_ANCHORS) -> np.ndarray:
    """Return the sorted vertex ids of the ``seen`` triangle ids (-1 ignored), at most ``max_anchors``.

    Parameters
    ----------
    triangles : (T, 3) int
        The mesh's triangles.
    seen : (n,) int
        Triangle ids (e.g. the one each region pixel's ray hits; -1: none).
    max_anchors : int
        A regular subset of the sorted ids is kept beyond this many.

    Raises
    ------
    InputError
        Fewer than 3 distinct vertices.
    """
    seen = np.asarray(seen).reshape(-1)
    ids = np.unique(np.asarray(triangles)[seen[seen >= 0]].reshape(-1))
    if ids.size < 3:
        raise InputError(f"the image size needs at least 3 seen vertices, got {ids.size}")
    if ids.size > max_anchors:
        ids = ids[np.linspace(0, ids.size - 1, max_anchors).round().astype(np.int64)]
    return ids


#: Generators of the rotations about x, y and z (``dR(t)/dt = G R(t)`` at the same axis).
_GX = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_GY = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
_GZ = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


def _rotation_derivatives(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """Return d R / d(yaw, pitch, roll) (3, 3, 3) of ``R = Rz(roll) Ry(yaw) Rx(pitch)``.

    With ``Rz Ry = R Rx^T``: ``dR/dyaw = R Rx^T G_y Rx``, ``dR/dpitch = R G_x``,
    ``dR/droll = G_z R``.
    """
    r = euler_rotation(roll, yaw, pitch)
    rx = euler_rotation(0.0, 0.0, pitch)
    return np.stack([r @ rx.T @ _GY @ rx, r @ _GX, _GZ @ r])


@dataclass(frozen=True, eq=False)
class ImageScale:
    """Log RMS radius, in pixels at unit focal length, of anchor vertices' projections.

    Build with :meth:`of_model`. Scene vectors ``x`` follow ``layout``; the view,
    image size, sensor and pose scaling are the template's (never sampled).

    Attributes
    ----------
    layout : SceneLayout
    template : RenderParameter
    mean : (n, 3) float64
        The anchors' mean positions (shape plus expression mean), model frame.
    shape_basis, expression_basis : (n, 3, k) float64
        Their scaled PCA bases (standard-normal coefficients).
    """

    layout: SceneLayout
    template: RenderParameter
    mean: np.ndarray
    shape_basis: np.ndarray
    expression_basis: np.ndarray

    @classmethod
    def of_model(cls, model: MorphableModel, params: RenderParameter,
                 vertex_ids: np.ndarray) -> ImageScale:
        """Return the image size of ``model``'s ``vertex_ids`` for fits laid out like ``params``.

        Raises
        ------
        InputError
            An orthographic camera (its image size does not depend on the
            distance; no ridge to straighten), or vertex ids out of range.
        """
        if params.camera.orthographic:
            raise InputError("the image-size coordinate is for perspective cameras")
        ids = np.asarray(vertex_ids, np.int64).reshape(-1)
        n_vertices = model.shape.dim // 3
        if ids.size < 3 or ids.min() < 0 or ids.max() >= n_vertices:
            raise InputError(f"anchor vertex ids must be >= 3 ids in [0, {n_vertices})")
        layout = SceneLayout.for_params(params)
        rows = (3 * ids[:, None] + np.arange(3)).reshape(-1)
        mean = model.shape.mean.astype(np.float64)[rows]
        eb = np.zeros((rows.size, layout.n_expression))
        if model.expression is not None:
            mean = mean + model.expression.mean.astype(np.float64)[rows]
            eb = model.expression.scaled_basis[rows, :layout.n_expression].astype(np.float64)
        sb = model.shape.scaled_basis[rows, :layout.n_shape].astype(np.float64)
        n = ids.size
        return cls(layout, params, mean.reshape(n, 3), sb.reshape(n, 3, -1),
                   eb.reshape(n, 3, -1))

    def _parts(self, x: np.ndarray):
        s = self.layout.slices()
        x = np.asarray(x, np.float64).reshape(-1)
        yaw, pitch, roll = x[s["angles"]]
        verts = (self.mean + self.shape_basis @ x[s["shape"]]
                 + self.expression_basis @ x[s["expression"]])
        rp = euler_rotation(roll, yaw, pitch)
        rv, tv = eye_from_world(self.template.view)
        scaling = float(self.template.pose.scaling)
        world = scaling * verts @ rp.T + x[s["translation"]]
        eye = world @ rv.T + tv
        return s, (yaw, pitch, roll), verts, rp, rv, scaling, eye

    def _unit_pixels(self, eye: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float] | None:
        unit = self.template.camera._replace(focal_length=1.0)
        kx, ky = pixel_scale(unit, self.template.image_size)
        depth = -eye[:, 2]
        if not np.all(depth > 0):
            return None
        q = np.stack([kx * eye[:, 0] / depth, -ky * eye[:, 1] / depth], axis=1)
        return q, depth, kx, ky

    def log_radius(self, x: np.ndarray) -> float:
        """Return the log RMS radius of the anchors' projections at unit focal length for scene vector ``x``.

        NaN where an anchor is not in front of the camera (outside the
        coordinate's domain: a move there is refused).
        """
        *_, eye = self._parts(x)
        unit = self._unit_pixels(eye)
        if unit is None:
            return math.nan
        q = unit[0] - unit[0].mean(axis=0)
        return 0.5 * float(np.log(np.mean(np.sum(q * q, axis=1))))

    def value_and_gradient(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """Return :meth:`log_radius` and its gradient in the scene vector (zero outside shape, expression, pose).

        NaN (value and gradient) outside the domain, as :meth:`log_radius`.
        """
        s, angles, verts, rp, rv, scaling, eye = self._parts(x)
        unit = self._unit_pixels(eye)
        if unit is None:
            return math.nan, np.full(self.layout.size, math.nan)
        q, depth, kx, ky = unit
        q = q - q.mean(axis=0)
        total = float(np.sum(q * q))
        value = 0.5 * float(np.log(total / q.shape[0]))
        gam = q / total  # d value / d q_i (the centroid's term sums to zero)
        g_eye = np.stack([gam[:, 0] * kx / depth, -gam[:, 1] * ky / depth,
                          (gam[:, 0] * kx * eye[:, 0] - gam[:, 1] * ky * eye[:, 1]) / depth ** 2],
                         axis=1)
        g_world = g_eye @ rv  # rows: R_v^T g
        g_model = scaling * g_world @ rp
        grad = np.zeros(self.layout.size)
        grad[s["translation"]] = g_world.sum(axis=0)
        grad[s["shape"]] = np.einsum("nj,njk->k", g_model, self.shape_basis)
        grad[s["expression"]] = np.einsum("nj,njk->k", g_model, self.expression_basis)
        outer = g_world.T @ verts  # sum_i g_i v_i^T
        grad[s["angles"]] = scaling * np.einsum("kab,ab->k", _rotation_derivatives(*angles), outer)
        return value, grad
