"""Crop a morphable model to a subset of its vertices (e.g. a face mask of a whole head).

A PCA part is a Gaussian ``x ~ N(mean, W W^T)`` with ``W = U diag(sqrt(var))``.
Its marginal over some rows is the Gaussian of those rows, ``N(mean_r, W_r
W_r^T)``: keeping the rows of the kept vertices is the *exact* marginal of the
full model, with the same standard-normal coefficients. :func:`crop_model`
keeps the chosen vertices (in their order in the full model), the triangles
whose three corners are kept (reindexed), the rows of every part, the
landmarks on kept vertices, the symmetry map among them and the UV atlas of the kept
triangles, and says in the
metadata what it was cropped from and how.

Orthonormality. :class:`~albedo_model.pca.PCAPart` documents orthonormal basis
columns, and :meth:`~albedo_model.pca.PCAPart.project` relies on them
(``U^T (x - mean)``); instances, samples, ``scaled_basis`` and
``marginal_std`` (all the renderer and the fit use) and the HDF5 writer and
reader do not (the writer stores the basis as given). The restricted rows
``U_r`` are no longer orthonormal, so the parts are re-expressed, exactly:

* **shape, expression** (and diffuse/specular with independent coefficients):
  the thin SVD ``W_r = Q S R`` gives the orthonormal basis ``Q`` with variances
  ``S^2`` and the same covariance ``W_r W_r^T``; the coefficients are rotated,
  ``c_crop = R c_full`` (``R`` orthogonal, so the N(0, I) prior is unchanged);
* **shared albedo** (AlbedoMM's transferred model, one coefficient vector for
  diffuse and specular): diffuse and specular must not be re-orthonormalised
  separately (two rotations would break the sharing), and a joint SVD of the
  stacked ``[diffuse; specular]`` rows would leave neither half orthonormal
  (the "concatenated" storage). Instead the *diffuse* rows are
  re-orthonormalised by their SVD, ``W_d = Q S R``, and the same rotation is
  applied to the specular rows, ``W_s R^T``, stored as unit-norm columns with
  variance = squared column norm (the convention of
  :mod:`pipeline.modelling.pca_variants` for the transferred specular part).
  The joint covariance of diffuse and specular, cross terms included, is
  unchanged (``[W_d; W_s] R^T R [W_d; W_s]^T``); the diffuse part is an
  orthonormal PCA again, and the specular modes are still the same linear
  combinations of the training samples as the diffuse modes. At full rank this
  is exactly the transferred model built from the cropped training maps.

A part's per-row residual variance (the out-of-span variance, when the model
has one) is per vertex and channel, so the crop keeps its rows of the kept
vertices unchanged: the span restricted to the kept rows is the restriction of
the span, and so is what lies outside it.

The SVD components are matched to the full model's (an assignment maximising
``|R_jj|``, each with ``R_jj > 0``), so component ``j`` of the crop is the one
closest to component ``j`` of the full model (a mode that lies inside the crop
stays mode ``j``; designed expression modes keep their meaning), rather than
being sorted by variance. :func:`crop_model_with_maps` returns the rotations.

This module imports only :mod:`albedo_model.errors`, :mod:`albedo_model.model`,
:mod:`albedo_model.pca` and SciPy.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Literal, NamedTuple

import numpy as np
from scipy.optimize import linear_sum_assignment

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.pca import PCAPart

__all__ = ["ModelCrop", "Unpaired", "crop_model", "crop_model_with_maps", "vertex_rows"]

Unpaired = Literal["drop", "error", "forget"]

#: How the parts are re-expressed (recorded in the metadata).
_BASIS_NOTE = ("rows of the kept vertices (the exact marginal); shape/expression re-orthonormalised "
               "by SVD; shared albedo rotated by the SVD of the diffuse rows (diffuse "
               "orthonormal, specular unit-norm columns); covariances unchanged")


class ModelCrop(NamedTuple):
    """A cropped model with the maps back to the full model.

    Attributes
    ----------
    model : MorphableModel
        The crop.
    vertex_index : (n_crop,) int64 array
        Vertex ``i`` of the crop is vertex ``vertex_index[i]`` of the full model.
    coefficient_maps : dict of str to (k_crop, k_full) float64 arrays
        ``c_crop = maps[name] @ c_full`` gives the crop's instance equal to the
        full model's instance on the kept vertices. Keys: ``shape``,
        ``expression``, ``albedo`` (the diffuse coefficients, which also drive a
        shared specular part) and ``specular`` (independent specular
        coefficients only). The rows are orthonormal.
    """

    model: MorphableModel
    vertex_index: np.ndarray
    coefficient_maps: dict[str, np.ndarray]


def vertex_rows(vertex_index: np.ndarray) -> np.ndarray:
    """Rows of a per-vertex interleaved vector (x0 y0 z0 x1 ...) for the given vertices."""
    v = np.asarray(vertex_index, np.int64)
    return (3 * v[:, None] + np.arange(3)).ravel()


def _svd(scaled: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thin SVD ``scaled = Q diag(s) R``, components matched to the columns (``R_jj > 0``)."""
    q, s, r = np.linalg.svd(scaled, full_matrices=False)
    rows, cols = linear_sum_assignment(-np.abs(r))
    order = rows[np.argsort(cols)]
    q, s, r = q[:, order], s[order], r[order]
    sign = np.where(r[np.arange(len(r)), np.arange(len(r))] < 0, -1.0, 1.0)
    return q * sign, s, r * sign[:, None]


def _part(part: PCAPart, rows: np.ndarray, mean: np.ndarray, basis: np.ndarray,
          variance: np.ndarray) -> PCAPart:
    residual = None if part.residual_variance is None else part.residual_variance[rows]
    return PCAPart(mean.astype(part.mean.dtype), basis.astype(part.basis.dtype),
                   variance.astype(part.variance.dtype), part.noise_variance, residual)


def _restricted(part: PCAPart, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean = part.mean.astype(np.float64)[rows]
    scaled = part.basis.astype(np.float64)[rows] * np.sqrt(part.variance.astype(np.float64))
    return mean, scaled


def _orthonormal_crop(part: PCAPart, rows: np.ndarray) -> tuple[PCAPart, np.ndarray]:
    mean, scaled = _restricted(part, rows)
    q, s, r = _svd(scaled)
    return _part(part, rows, mean, q, s**2), r


def _rotated_crop(part: PCAPart, rows: np.ndarray, rotation: np.ndarray) -> PCAPart:
    """Rows of ``part`` driven by rotated coefficients: unit columns, variance = squared norm."""
    mean, scaled = _restricted(part, rows)
    scaled = scaled @ rotation.T
    norms = np.linalg.norm(scaled, axis=0)
    return _part(part, rows, mean, scaled / np.where(norms > 0, norms, 1.0), norms**2)


def _kept_vertices(model: MorphableModel, keep) -> np.ndarray:
    k = np.asarray(keep)
    if k.dtype == bool:
        if k.shape != (model.n_vertices,):
            raise InputError(f"a vertex mask must have shape ({model.n_vertices},), got {k.shape}")
        return np.flatnonzero(k)
    if k.ndim != 1 or (k.size and k.dtype.kind not in "iu"):
        raise InputError("keep must be a boolean vertex mask or a 1-D array of vertex indices")
    if k.size and (k.min() < 0 or k.max() >= model.n_vertices):
        raise InputError(f"vertex indices out of range [0, {model.n_vertices})")
    return np.unique(k.astype(np.int64))


def _landmarks(model: MorphableModel, kept: np.ndarray) -> tuple[dict, list[str]]:
    """Landmarks whose vertex is kept (one off the mesh: whose nearest vertex is kept)."""
    on_vertex = model.landmark_vertices
    verts = model.vertices.astype(np.float64)
    out, dropped = {}, []
    for name, p in model.landmarks.items():
        i = on_vertex.get(name)
        if i is None:
            i = int(np.argmin(((verts - p) ** 2).sum(1)))
        if kept[i]:
            out[name] = p
        else:
            dropped.append(name)
    return out, dropped


def crop_model_with_maps(
    model: MorphableModel, keep, *, unpaired: Unpaired = "drop", source: str = "",
    region: str = "",
) -> ModelCrop:
    """Crop ``model`` to a vertex subset; also return the vertex and coefficient maps.

    Parameters
    ----------
    model : MorphableModel
    keep : (n,) bool array or 1-D int array
        The vertices to keep (a mask, or indices; kept in the full model's order).
    unpaired : {"drop", "error", "forget"}
        What to do with kept vertices whose mirror vertex (``model.symmetry``)
        is not kept: ``"drop"`` them too (default; the crop stays mirror
        symmetric and its symmetry map is the full one restricted),
        ``"error"`` (raise), or ``"forget"`` the symmetry map (``None``).
        Ignored when the model has no symmetry map.
    source : str
        What was cropped (a model name, file, checksum), for the metadata.
    region : str
        How the vertices were chosen, for the metadata.

    Returns
    -------
    ModelCrop

    Raises
    ------
    InputError
        Nothing is kept, too few vertices for the parts' ranks (3 x kept
        vertices must be at least every part's rank), or an unpaired vertex
        with ``unpaired="error"``.
    """
    if unpaired not in ("drop", "error", "forget"):
        raise InputError(f"unpaired must be 'drop', 'error' or 'forget', not {unpaired!r}")
    idx = _kept_vertices(model, keep)
    kept = np.zeros(model.n_vertices, bool)
    kept[idx] = True
    symmetry, n_unpaired = model.symmetry, 0
    if symmetry is not None:
        lonely = kept & ~kept[symmetry]
        n_unpaired = int(lonely.sum())
        if n_unpaired and unpaired == "error":
            raise InputError(f"{n_unpaired} kept vertices have their mirror vertex dropped")
        if unpaired == "drop":
            kept &= ~lonely
        elif unpaired == "forget" and n_unpaired:
            symmetry = None
        idx = np.flatnonzero(kept)
    if idx.size == 0:
        raise InputError("the crop keeps no vertex")
    if 3 * idx.size < max(model.ranks.values()):
        raise InputError(f"{idx.size} vertices are too few for parts of rank "
                         f"{max(model.ranks.values())}")
    remap = np.full(model.n_vertices, -1, np.int64)
    remap[idx] = np.arange(idx.size)
    kept_tri = np.all(kept[model.triangles], axis=1)
    tri = model.triangles[kept_tri]
    rows = vertex_rows(idx)

    parts, maps = {}, {}
    parts["shape"], maps["shape"] = _orthonormal_crop(model.shape, rows)
    if model.expression is not None:
        parts["expression"], maps["expression"] = _orthonormal_crop(model.expression, rows)
    parts["diffuse"], maps["albedo"] = _orthonormal_crop(model.diffuse, rows)
    if model.specular is not None:
        if model.shared_albedo:  # equal ranks (MorphableModel checks): one rotation drives both
            parts["specular"] = _rotated_crop(model.specular, rows, maps["albedo"])
        else:
            parts["specular"], maps["specular"] = _orthonormal_crop(model.specular, rows)

    landmarks, dropped = _landmarks(model, kept)
    record = {
        "source": source, "region": region, "vertices": [int(idx.size), model.n_vertices],
        "triangles": [len(tri), model.n_triangles], "landmarks_dropped": dropped,
        "unpaired_vertices": {"policy": unpaired, "count": n_unpaired}, "basis": _BASIS_NOTE,
    }
    metadata = {**model.metadata, "crop": json.dumps(record, sort_keys=True)}
    cropped = dataclasses.replace(
        model, vertices=model.vertices[idx], triangles=remap[tri], **parts, landmarks=landmarks,
        symmetry=None if symmetry is None else remap[symmetry[idx]], metadata=metadata,
        uv_atlas=None if model.uv_atlas is None else model.uv_atlas.restricted(kept_tri),
    )
    return ModelCrop(cropped, idx, maps)


def crop_model(model: MorphableModel, keep, **options) -> MorphableModel:
    """Crop ``model`` to a vertex subset (see :func:`crop_model_with_maps` for the options).

    Returns
    -------
    MorphableModel
        The exact marginal of ``model`` on the kept vertices, with re-orthonormalised
        parts (see the module docstring); its coefficients are rotations of the
        full model's.
    """
    return crop_model_with_maps(model, keep, **options).model
