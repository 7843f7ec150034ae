"""Derived monitored quantities: the mean diffuse albedo of each face region, per draw.

The diffuse albedo is linear in the albedo coefficients c (``mean + U diag(sqrt(var)) c``,
:class:`albedo_model.pca.PCAPart`), so the area-weighted mean over a region R is
``m_R + c @ B_R`` with the (3,) mean ``m_R`` and the (k, 3) basis ``B_R`` averaged
once over the region's vertices (:func:`region_albedo_basis`). Over a chain's
draws it is one (n_draws, k) @ (k, 3 R) product (:func:`region_albedo_means`).
Vertex areas are one third of the adjacent triangles' areas on the mean shape,
so that a finely meshed part of a region does not outweigh the rest. Regions
are those of :func:`albedo_model.regions.face_regions`; the quantities are named
``albedo_mean.<region>.<r|g|b>`` (linear sRGB, as the model's diffuse part).

This module imports :mod:`albedo_model` (errors, model, regions) and
:mod:`mcmcfit.sampling.param_vector`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.regions import face_regions
from mcmcfit.sampling.param_vector import ParamLayout

__all__ = ["PREFIX", "RegionAlbedo", "region_albedo_basis", "region_albedo_means",
           "region_albedo_series", "vertex_areas"]

#: Name prefix of the derived quantities.
PREFIX = "albedo_mean"
_CHANNELS = "rgb"


class RegionAlbedo(NamedTuple):
    """Precomputed region means of a model's diffuse albedo.

    Attributes
    ----------
    regions : tuple of str
        Region names (R).
    mean : (R, 3) float64
        Region mean of the mean albedo.
    basis : (R, k, 3) float64
        Region mean of each scaled basis column (k = the diffuse rank).
    """

    regions: tuple[str, ...]
    mean: np.ndarray
    basis: np.ndarray

    @property
    def names(self) -> tuple[str, ...]:
        """Quantity names ``albedo_mean.<region>.<channel>``, region-major."""
        return tuple(f"{PREFIX}.{r}.{c}" for r in self.regions for c in _CHANNELS)


def vertex_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """One third of the summed area of each vertex's triangles, (n,) float64."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles)
    area = 0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1)
    return np.bincount(t.reshape(-1), weights=np.repeat(area / 3.0, 3), minlength=v.shape[0])


def region_albedo_basis(model: MorphableModel,
                        regions: dict[str, np.ndarray] | None = None) -> RegionAlbedo:
    """Region means of ``model``'s diffuse mean and scaled basis.

    Parameters
    ----------
    model : MorphableModel
    regions : mapping name -> (n_vertices,) bool, optional
        Default :func:`albedo_model.regions.face_regions` of the model.

    Returns
    -------
    RegionAlbedo
        With no region at all (a model without the landmarks), R = 0.
    """
    masks = face_regions(model) if regions is None else dict(regions)
    part = model.diffuse
    n, k = model.n_vertices, part.rank
    if not masks:
        return RegionAlbedo((), np.zeros((0, 3)), np.zeros((0, k, 3)))
    area = vertex_areas(model.shape_instance(), model.triangles)
    w = np.stack([np.where(m, area, 0.0) for m in masks.values()])  # (R, n)
    w /= w.sum(axis=1, keepdims=True)
    mean = w @ part.mean.astype(np.float64).reshape(n, 3)
    basis = (w @ part.scaled_basis.astype(np.float64).reshape(n, 3 * k)).reshape(-1, 3, k)
    return RegionAlbedo(tuple(masks), mean, np.ascontiguousarray(basis.transpose(0, 2, 1)))


def region_albedo_means(coefficients: np.ndarray, basis: RegionAlbedo) -> np.ndarray:
    """Mean diffuse albedo of every region for each coefficient vector.

    Parameters
    ----------
    coefficients : (..., j) float, j <= k
        Albedo coefficients (missing trailing ones are zero).
    basis : RegionAlbedo

    Returns
    -------
    (..., R, 3) float64, linear.
    """
    c = np.asarray(coefficients, np.float64)
    r, k, _ = basis.basis.shape
    j = c.shape[-1]
    if j > k:
        raise InputError(f"{j} albedo coefficients for a rank-{k} diffuse part")
    flat = basis.basis[:, :j, :].transpose(1, 0, 2).reshape(j, 3 * r)
    return (c @ flat).reshape(*c.shape[:-1], r, 3) + basis.mean


def region_albedo_series(samples: np.ndarray, layout: ParamLayout,
                         basis: RegionAlbedo) -> dict[str, np.ndarray]:
    """Return the derived quantities of sample vectors, by name.

    Parameters
    ----------
    samples : (..., d) float
        Parameter vectors in ``layout`` (e.g. (chains, draws, d)).
    layout : ParamLayout
    basis : RegionAlbedo

    Returns
    -------
    dict ``albedo_mean.<region>.<channel>`` -> (...) float64
    """
    s = np.asarray(samples, np.float64)
    means = region_albedo_means(s[..., layout.slice("albedo")], basis)
    flat = means.reshape(*means.shape[:-2], -1)
    return {name: flat[..., i] for i, name in enumerate(basis.names)}
