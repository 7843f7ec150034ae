"""PCA models of diffuse and specular albedo: the paper's three variants.

Smith et al. 2020, "Statistical modelling", compare three ways of modelling
specular albedo beside diffuse albedo:

``independent``
    Two PCA models, each with its own coefficient vector.
``concatenated``
    One PCA of the stacked ``[diffuse; specular]`` vectors; one coefficient
    vector drives both halves. The halves of the joint eigenvectors are not
    orthonormal on their own (the paper's objection: the diffuse part alone is
    no longer an orthonormal model).
``transferred`` (AlbedoMM's released model)
    PCA of diffuse only; the specular "principal components are made from the
    same linear combinations of training samples as the diffuse modes", so the
    diffuse coefficients also drive specular and the diffuse model keeps its
    optimality and orthonormality. With centred data ``X_d = U S V^T`` the
    diffuse modes are ``X_d^T U S^-1``; the specular modes are ``X_s^T U S^-1``.
    In standard-normal coordinates ``C = sqrt(N-1) U`` (``C^T C = (N-1) I``) the
    specular scaled basis is ``X_s^T C / (N-1)``, which is exactly the
    least-squares regression of the specular data on the diffuse coefficients.
    At full rank the model reproduces every training subject's specular map from
    that subject's diffuse coefficients, and its specular covariance equals the
    sample covariance.

Storage: a :class:`~albedo_model.pca.PCAPart` is ``mean + B diag(sqrt(var)) c``.
For the two shared variants the specular part (and, for ``concatenated``, the
diffuse part too) gets unit-norm but mutually non-orthogonal basis columns,
with ``var_j`` the variance that mode ``j`` contributes to that part, so that
one coefficient vector gives the right instance in both parts. Instances,
samples and marginal standard deviations are then exact; orthogonal
:meth:`PCAPart.project` is not meaningful for such a part (fit coefficients
through the diffuse part instead).

Symmetry augmentation (paper: "we include each sample twice, once as
captured, once reflected"): a mirrored albedo map is the map read through the
template's symmetry permutation (colours are not reflected, only moved). The
augmented data set is closed under mirroring, so its mean is symmetric and the
PCA span is mirror-invariant.

Maps are (S, n, 3) arrays in linear sRGB and are flattened per vertex
interleaved (r0 g0 b0 r1 ...), the PCAPart layout.

This module imports only :mod:`albedo_model` (``errors``, ``pca``).
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.pca import PCAPart, pca_from_data

__all__ = [
    "VARIANTS", "AlbedoParts", "Variant", "augment_with_mirror", "build_albedo_parts",
    "mirror_maps",
]

Variant = Literal["independent", "concatenated", "transferred"]
VARIANTS: tuple[str, ...] = ("independent", "concatenated", "transferred")


class AlbedoParts(NamedTuple):
    """Diffuse and specular PCA parts and whether they share coefficients.

    Attributes
    ----------
    diffuse, specular : PCAPart
        Dimension 3n each, per-vertex interleaved.
    shared : bool
        One coefficient vector drives both (``concatenated``, ``transferred``).
    """

    diffuse: PCAPart
    specular: PCAPart
    shared: bool


def _check_maps(maps: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(maps, np.float64)
    if a.ndim != 3 or a.shape[2] != 3:
        raise InputError(f"{name} maps must have shape (subjects, vertices, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} maps contain NaN or infinite values")
    return a


def _check_symmetry(symmetry: np.ndarray, n: int) -> np.ndarray:
    s = np.asarray(symmetry)
    if s.shape != (n,) or s.dtype.kind not in "iu" or s.min() < 0 or s.max() >= n:
        raise InputError(f"symmetry map must be an index array of shape ({n},)")
    if not np.array_equal(s[s], np.arange(n)):
        raise InputError("symmetry map must be an involution (symmetry[symmetry[i]] == i)")
    return s


def mirror_maps(maps: np.ndarray, symmetry: np.ndarray) -> np.ndarray:
    """Per-vertex maps of the mirrored faces: ``out[..., i, :] = maps[..., symmetry[i], :]``.

    Parameters
    ----------
    maps : (..., n, 3) array
    symmetry : (n,) int array, involution

    Returns
    -------
    (..., n, 3) array
    """
    m = np.asarray(maps)
    return m[..., _check_symmetry(symmetry, m.shape[-2]), :]


def augment_with_mirror(maps: np.ndarray, symmetry: np.ndarray) -> np.ndarray:
    """Symmetry augmentation: the S maps followed by their S mirror images, (2S, n, 3)."""
    m = _check_maps(maps, "albedo")
    return np.concatenate([m, mirror_maps(m, symmetry)], axis=0)


def _unit_columns(scaled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split a scaled basis ``B diag(sqrt(var))`` into unit columns and variances."""
    norms = np.linalg.norm(scaled, axis=0)
    safe = np.where(norms > 0, norms, 1.0)
    return scaled / safe, norms**2


def build_albedo_parts(
    diffuse: np.ndarray,
    specular: np.ndarray,
    symmetry: np.ndarray | None,
    *,
    variant: Variant = "transferred",
    rank: int | None = None,
) -> AlbedoParts:
    """PCA of diffuse and specular albedo in one of the paper's three variants.

    Parameters
    ----------
    diffuse, specular : (S, n, 3) arrays
        Per-vertex albedo of S subjects, linear sRGB.
    symmetry : (n,) int array or None
        Mirror partner of each vertex. Given: every subject is used twice,
        as is and mirrored (2S samples). ``None``: no augmentation.
    variant : {"independent", "concatenated", "transferred"}
    rank : int, optional
        Keep at most this many components (default: all, i.e. up to 2S - 1).

    Returns
    -------
    AlbedoParts
        ``shared`` is False only for ``independent``. For ``transferred`` and
        ``concatenated`` both parts have the same rank.
    """
    d = _check_maps(diffuse, "diffuse")
    s = _check_maps(specular, "specular")
    if d.shape != s.shape:
        raise InputError(f"diffuse maps {d.shape} and specular maps {s.shape} differ in shape")
    if variant not in VARIANTS:
        raise InputError(
            f"unknown albedo model variant {variant!r}; use one of {', '.join(VARIANTS)}"
        )
    if symmetry is not None:
        d = augment_with_mirror(d, symmetry)
        s = augment_with_mirror(s, symmetry)
    n_samples = d.shape[0]
    xd = d.reshape(n_samples, -1)
    xs = s.reshape(n_samples, -1)

    if variant == "independent":
        return AlbedoParts(pca_from_data(xd, rank=rank), pca_from_data(xs, rank=rank), False)

    if variant == "concatenated":
        joint = pca_from_data(np.hstack([xd, xs]), rank=rank)
        dim = xd.shape[1]
        scaled = joint.scaled_basis
        parts = []
        for block, mean in ((scaled[:dim], joint.mean[:dim]), (scaled[dim:], joint.mean[dim:])):
            basis, var = _unit_columns(block)
            parts.append(PCAPart(mean, basis, var))
        return AlbedoParts(parts[0], parts[1], True)

    diff = pca_from_data(xd, rank=rank)
    coeffs = diff.project(xd, regularization=0.0)          # (N, k), C^T C = (N-1) I
    mean_s = xs.mean(axis=0)
    scaled = (xs - mean_s).T @ coeffs / (n_samples - 1)      # regression of specular on C
    basis, var = _unit_columns(scaled)
    return AlbedoParts(diff, PCAPart(mean_s, basis, var), True)
