"""Gradient and Gauss-Newton precision of a joint posterior: every image's, side by side.

:class:`JointCurvature` holds one :class:`~mcmcfit.targets.curvature.PosteriorCurvature`
per image (each over its image's fixed pixel region) and returns their
curvatures as tuples, in each image's own scene vector, for
:meth:`proposals.laplace.joint_coordinates.JointCoordinates.to_coordinates`,
which sums them in the joint coordinates (the identity's prior counted once).
Region pixels are numbered across the images (image ``i``'s pixel ``p`` is
``offset[i] + p``), so that :func:`mcmcfit.fitting.mode.find_mode`'s random
pixel subsets draw from every image's region alike.

This module imports :mod:`albedo_model.errors`, :mod:`mcmcfit.targets.curvature`
and :mod:`proposals.joint`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from mcmcfit.targets.curvature import Curvature, PosteriorCurvature
from proposals.joint import JointParameter

__all__ = ["JointCurvature", "JointCurvatures", "joint_coordinate_gradient"]


class JointCurvatures(NamedTuple):
    """Per-image curvatures in the fields of :class:`~mcmcfit.targets.curvature.Curvature`."""

    gradient: tuple[np.ndarray, ...]
    precision: tuple[np.ndarray, ...]
    pixels: int
    exact_gradient: tuple[np.ndarray | None, ...]


class JointCurvature:
    """Per-image posterior curvatures of a joint fit.

    Parameters
    ----------
    images : sequence of PosteriorCurvature
        One per image, in the joint state's order.
    """

    def __init__(self, images: Sequence[PosteriorCurvature]):
        if not len(images):
            raise InputError("a joint curvature needs at least one image")
        self.images = tuple(images)
        sizes = [int(c.target.image_likelihood.region.size) for c in self.images]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self._region = np.concatenate([c.region_pixels + o
                                       for c, o in zip(self.images, self.offsets)])

    @property
    def region_pixels(self) -> np.ndarray:
        """Every image's region pixels, numbered across the images."""
        return self._region

    def at(self, params: JointParameter, *, pixels: np.ndarray | None = None,
           weight: float = 1.0) -> JointCurvatures:
        """Return every image's curvature at its scene (``pixels``: a subset, numbered jointly)."""
        if params.n_images != len(self.images):
            raise InputError(f"the joint state has {params.n_images} images, the curvature "
                             f"{len(self.images)}")
        parts: list[Curvature] = []
        for i, (c, p) in enumerate(zip(self.images, params.images)):
            sub = None
            if pixels is not None:
                pix = np.asarray(pixels, np.int64)
                mine = pix[(pix >= self.offsets[i]) & (pix < self.offsets[i + 1])]
                sub = mine - self.offsets[i]
            parts.append(c.at(p, pixels=sub, weight=weight))
        return JointCurvatures(tuple(c.gradient for c in parts), tuple(c.precision for c in parts),
                               int(sum(c.pixels for c in parts)),
                               tuple(c.exact_gradient for c in parts))

    def region_triangles(self, params: JointParameter) -> tuple[np.ndarray, ...]:
        """Return, per image, the triangle each of its region pixels sees at its scene."""
        return tuple(c.region_triangles(p) for c, p in zip(self.images, params.images))


def joint_coordinate_gradient(curvature: JointCurvature, coords,
                              triangles: Sequence[np.ndarray] | None = None):
    """Return ``grad(params) -> (log density, gradient)`` of the joint posterior in ``coords``.

    ``coords`` is a :class:`proposals.laplace.joint_coordinates.JointCoordinates`;
    the density includes ``log |dx/du|`` and counts the identity's prior once;
    ``triangles`` (per image) as :meth:`PosteriorCurvature.image_gradient`.
    For :class:`proposals.laplace.moves.GaussianHMC`.
    """
    tri = triangles if triangles is not None else [None] * len(curvature.images)

    def grad(params: JointParameter) -> tuple[float, np.ndarray]:
        values, grads = [], []
        for c, p, t in zip(curvature.images, params.images, tri, strict=True):
            v, g = c.value_and_gradient(p, t)
            values.append(v)
            grads.append(g)
        u = coords.u_of(params)
        shared = u[coords.shared]
        duplicate = -0.5 * (coords.n_images - 1) * float(shared @ shared)
        value = float(sum(values)) - duplicate + coords.log_jacobian(u)
        return value, coords.gradient(grads, u)

    return grad
