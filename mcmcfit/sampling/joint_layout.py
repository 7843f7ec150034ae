"""Flat vectors of a joint fit's parameters: the identity once, then every image's own columns.

Columns: ``shape.<i>`` and ``albedo.<i>`` (shared), then for each image ``k``
its :class:`~mcmcfit.sampling.param_vector.ParamLayout` columns but the shared
ones, named ``image<k>.<name>`` (``image1.pose.yaw``, ``image0.light.0.r``, ...).
Chain records, convergence diagnostics and the regions' mean albedo read it as
they read a single fit's layout (``names``, ``size``, ``index``, ``slice``,
``n_albedo``, ``to_vector``, ``from_vector``).

This module imports :mod:`albedo_model.errors`, :mod:`mcmcfit.sampling.param_vector`
and :mod:`proposals.joint`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from albedo_model.errors import InputError
from mcmcfit.sampling.param_vector import ParamLayout
from proposals.joint import JointParameter

__all__ = ["JointParamLayout"]


@dataclass(frozen=True)
class JointParamLayout:
    """Column layout of a joint fit's parameter vectors.

    Attributes
    ----------
    image : ParamLayout
        Every image's own layout (the images of a joint fit have the same block sizes).
    n_images : int
    """

    image: ParamLayout
    n_images: int

    @classmethod
    def for_params(cls, params: JointParameter) -> JointParamLayout:
        """Return the layout of a joint state's block sizes."""
        layouts = {ParamLayout.for_params(p) for p in params.images}
        if len(layouts) != 1:
            raise InputError("the images of a joint fit need the same block sizes")
        return cls(layouts.pop(), params.n_images)

    @property
    def n_albedo(self) -> int:
        """Albedo coefficients sampled."""
        return self.image.n_albedo

    @property
    def n_shape(self) -> int:
        """Shape coefficients sampled."""
        return self.image.n_shape

    def _own(self) -> np.ndarray:
        """Columns of an image's layout that are its own (not shape or albedo)."""
        cols = np.ones(self.image.size, bool)
        cols[self.image.slice("shape")] = False
        cols[self.image.slice("albedo")] = False
        return np.flatnonzero(cols)

    @property
    def names(self) -> tuple[str, ...]:
        """Column names, in order."""
        own = [self.image.names[j] for j in self._own()]
        return (tuple(f"shape.{i}" for i in range(self.n_shape))
                + tuple(f"albedo.{i}" for i in range(self.n_albedo))
                + tuple(f"image{k}.{n}" for k in range(self.n_images) for n in own))

    @property
    def size(self) -> int:
        """Number of columns."""
        return self.n_shape + self.n_albedo + self.n_images * len(self._own())

    def index(self, name: str) -> int:
        """Column of ``name``."""
        try:
            return self.names.index(name)
        except ValueError:
            raise InputError(f"no parameter column {name!r}") from None

    def slice(self, block: str) -> slice:
        """Columns of the shared ``"shape"`` or ``"albedo"``."""
        if block == "shape":
            return slice(0, self.n_shape)
        if block == "albedo":
            return slice(self.n_shape, self.n_shape + self.n_albedo)
        raise InputError(f"a joint layout has one {block!r} per image: use image_columns")

    def image_columns(self, k: int) -> np.ndarray:
        """Columns of the joint vector that make image ``k``'s vector (in its own layout's order)."""
        cols = np.empty(self.image.size, np.int64)
        cols[self.image.slice("shape")] = np.arange(self.n_shape)
        cols[self.image.slice("albedo")] = self.n_shape + np.arange(self.n_albedo)
        n_own = len(self._own())
        cols[self._own()] = self.n_shape + self.n_albedo + k * n_own + np.arange(n_own)
        return cols

    def to_vector(self, params: JointParameter) -> np.ndarray:
        """(size,) float64 vector of a joint state."""
        if params.n_images != self.n_images:
            raise InputError(f"the joint state has {params.n_images} images, the layout "
                             f"{self.n_images}")
        out = np.empty(self.size)
        for k, p in enumerate(params.images):
            out[self.image_columns(k)] = self.image.to_vector(p)
        return out

    def from_vector(self, vector: np.ndarray, template: JointParameter) -> JointParameter:
        """Return the joint state with the sampled fields from ``vector``, the rest from ``template``."""
        v = np.asarray(vector, np.float64).reshape(-1)
        if v.shape[0] != self.size:
            raise InputError(f"parameter vector has {v.shape[0]} values, layout needs {self.size}")
        return JointParameter.share([self.image.from_vector(v[self.image_columns(k)], p)
                                     for k, p in enumerate(template.images)])

    def image_vectors(self, samples: np.ndarray, k: int) -> np.ndarray:
        """Image ``k``'s columns of sample vectors (..., size), in its own layout (..., d)."""
        return np.asarray(samples)[..., self.image_columns(k)]
