"""Sampling coordinates of a joint fit: the shared identity once, then every image's own.

Each image keeps its :class:`~proposals.laplace.coordinates.SamplingCoordinates`
(its own template, log scales and image size). The shape and albedo
coefficients are coordinates of every image, mapped to themselves; the joint
vector holds them once::

    u = [u_shared | u_own(image 0) | u_own(image 1) | ...]

and image ``i``'s coordinates are ``u[index[i]]``. The joint log density is
the sum of the images' log densities (each with its log-Jacobian; the shared
coordinates add none) minus the identity's N(0, I) prior counted ``N - 1``
times too often, so gradients and precisions in ``u`` are the images' own,
scattered into the joint vector and summed, with that correction
(:meth:`JointCoordinates.to_coordinates`). The moves of
:mod:`proposals.laplace.moves` read only ``size``, ``names``, ``touches``,
``u_of``, ``params_of``, ``log_jacobian`` and ``blocks_of``, so they run on
these coordinates unchanged, and so do the climb to the mode and the Laplace
approximation of :mod:`mcmcfit.fitting.mode`, given per-image curvatures.

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.params`,
:mod:`proposals.joint` and :mod:`proposals.laplace.coordinates`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import Block
from proposals.joint import JointParameter
from proposals.laplace.coordinates import SamplingCoordinates

__all__ = ["JointCoordinates", "image_name"]

#: Coordinate-name prefixes of the shared identity.
_SHARED_PREFIXES = ("shape.", "albedo.")


def image_name(i: int, name: str) -> str:
    """Joint name of image ``i``'s own coordinate ``name`` (``"image1.pose.yaw"``-like)."""
    return f"image{i}.{name}"


class JointCoordinates:
    """``u <-> JointParameter`` over per-image sampling coordinates (see the module notes).

    Parameters
    ----------
    images : sequence of SamplingCoordinates
        One per image, in the joint state's order; their shared coordinates
        (names ``shape.*``, ``albedo.*``) must be the same in every image.

    Attributes
    ----------
    names : tuple of str
        The shared coordinates' names, then ``image<i>.<name>`` of every image's own.
    index : tuple of (d_i,) int arrays
        Where image ``i``'s coordinates sit in ``u``.
    shared : (size,) bool
        The shared coordinates.
    touches : Block
    """

    def __init__(self, images: Sequence[SamplingCoordinates]):
        if not len(images):
            raise InputError("joint coordinates need at least one image")
        self.images = tuple(images)
        first = [n for n in self.images[0].names if n.startswith(_SHARED_PREFIXES)]
        names, index = list(first), []
        for i, c in enumerate(self.images):
            shared_here = [n for n in c.names if n.startswith(_SHARED_PREFIXES)]
            if shared_here != first:
                raise InputError(f"image {i} samples other shared coordinates than image 0")
            idx = []
            for n in c.names:
                if n.startswith(_SHARED_PREFIXES):
                    idx.append(first.index(n))
                else:
                    idx.append(len(names))
                    names.append(image_name(i, n))
            index.append(np.asarray(idx, np.int64))
        self.names = tuple(names)
        self.index = tuple(index)
        self.shared = np.zeros(len(names), bool)
        self.shared[:len(first)] = True
        touches = Block.NONE
        for c in self.images:
            touches |= c.touches
        self.touches = touches

    @property
    def size(self) -> int:
        """Number of joint coordinates."""
        return len(self.names)

    @property
    def n_images(self) -> int:
        """Number of images."""
        return len(self.images)

    def _check(self, u: np.ndarray) -> np.ndarray:
        u = np.asarray(u, np.float64).reshape(-1)
        if u.shape[0] != self.size:
            raise InputError(f"coordinate vector has {u.shape[0]} entries, expected {self.size}")
        return u

    def u_of(self, params: JointParameter) -> np.ndarray:
        """Return the joint coordinates of a joint state."""
        if params.n_images != self.n_images:
            raise InputError(f"the joint state has {params.n_images} images, the coordinates "
                             f"{self.n_images}")
        u = np.zeros(self.size)
        for c, idx, p in zip(self.images, self.index, params.images):
            u[idx] = c.u_of(p)
        return u

    def params_of(self, u: np.ndarray, base: JointParameter | None = None) -> JointParameter:
        """Return the joint state of ``u`` (other fields from ``base``, default the templates).

        An image whose coordinates equal ``base``'s is kept as the same object
        (the joint target then does not render it again), and every image
        holds the same shape and albedo arrays.
        """
        u = self._check(u)
        if base is None:
            return JointParameter.share([c.params_of(u[idx]) for c, idx in
                                         zip(self.images, self.index)])
        images, changed = [], False
        for c, idx, p in zip(self.images, self.index, base.images, strict=True):
            ui = u[idx]
            if np.array_equal(ui, c.u_of(p)):
                images.append(p)
            else:
                images.append(c.params_of(ui, p))
                changed = True
        if not changed:
            return base
        if not np.array_equal(u[self.shared], self.u_of(base)[self.shared]):
            return JointParameter.share(images)  # the identity moved: every image changed
        momo = base.images[0].momo  # the identity kept: the same arrays as before everywhere
        return JointParameter(tuple(
            p if p is old else p._replace(momo=p.momo._replace(shape=momo.shape,
                                                               albedo=momo.albedo))
            for p, old in zip(images, base.images)))

    def log_jacobian(self, u: np.ndarray) -> float:
        """Return ``log |dx/du|``, summed over the images (the shared coordinates add none)."""
        u = self._check(u)
        return float(sum(c.log_jacobian(u[idx]) for c, idx in zip(self.images, self.index)))

    def _duplicate_prior(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gradient and precision of the identity's N(0, I) prior counted ``N - 1`` extra times."""
        k = self.n_images - 1
        g = np.where(self.shared, -k * u, 0.0)
        return g, np.diag(np.where(self.shared, float(k), 0.0))

    def gradient(self, gradients_x: Sequence[np.ndarray], u: np.ndarray) -> np.ndarray:
        """Return the joint log density's gradient in ``u`` from every image's gradient in its x."""
        u = self._check(u)
        out = np.zeros(self.size)
        for c, idx, g in zip(self.images, self.index, gradients_x, strict=True):
            np.add.at(out, idx, c.gradient(g, u[idx]))
        return out - self._duplicate_prior(u)[0]

    def to_coordinates(self, gradient_x: Sequence[np.ndarray], precision_x: Sequence[np.ndarray],
                       u: np.ndarray, *, second_order: Sequence[np.ndarray | None] | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Turn every image's gradient and precision in its x into the joint ones in ``u``.

        Each image's terms are turned by its own coordinates
        (:meth:`SamplingCoordinates.to_coordinates`), scattered into ``u`` and
        summed; the identity's prior, which every image's terms include, is
        then removed ``N - 1`` times.
        """
        u = self._check(u)
        second = second_order if second_order is not None else [None] * self.n_images
        grad, prec = np.zeros(self.size), np.zeros((self.size, self.size))
        for c, idx, g, h, s in zip(self.images, self.index, gradient_x, precision_x, second,
                                   strict=True):
            gi, hi = c.to_coordinates(g, h, u[idx], second_order=s)
            np.add.at(grad, idx, gi)
            prec[np.ix_(idx, idx)] += hi
        dg, dh = self._duplicate_prior(u)
        return grad - dg, prec - dh

    def blocks_of(self, mask: np.ndarray) -> Block:
        """Return the blocks of the coordinates selected by a boolean ``mask``."""
        mask = np.asarray(mask, bool).reshape(-1)
        out = Block.NONE
        for c, idx in zip(self.images, self.index):
            out |= c.blocks_of(mask[idx])
        return out

    def image_of(self, mask: np.ndarray) -> set[int]:
        """Return the images whose own coordinates ``mask`` selects (shared ones: every image)."""
        mask = np.asarray(mask, bool).reshape(-1)
        if np.any(mask & self.shared):
            return set(range(self.n_images))
        return {i for i, idx in enumerate(self.index) if np.any(mask[idx])}
