"""Out-of-span residual variance of an albedo PCA, estimated by leave-one-out.

A PCA part of rank ``k`` represents a face's albedo only up to what lies
outside its span. Probabilistic PCA models that remainder as isotropic noise
``sigma^2``; here it is made per row (per vertex and channel) and estimated
*out of sample*, so that it measures how far an unseen face lies from the
model, not how far the training faces do (those are in the span at full rank):

for every training subject ``i``, build the model of the other subjects (same
variant, same symmetry augmentation, same rank ``k``), fit it to the held-out
subject's albedo, and take the residual; the residual variance of a row is the
mean over held-out samples of the squared residual. With symmetry
augmentation both copies of subject ``i`` (as captured and mirrored) are held
out together and both are scored, so the estimate is mirror symmetric.

The fit of a held-out sample is the one a photograph fit makes: the
coefficients that best explain its diffuse map (orthogonal projection for the
``independent`` and ``transferred`` variants, least squares on the
non-orthonormal diffuse half for ``concatenated``), and the specular map
predicted at the same coefficients when the variant shares them; the
``independent`` specular part is fitted to the held-out specular map with its
own coefficients.

Computation. Every mode of every split is a linear combination of training
samples, so a split is solved on the (augmented) samples' Gram matrix
(:class:`pipeline.modelling.generalisation.GramFold`, shared with the
generalisation curves): a held-out sample's fit is ``X^T w`` for a weight
vector ``w`` over the samples (zero on the held-out ones, summing to one, the
fold mean included). One pass forms the Gram matrix, each split costs an
eigendecomposition of an ``(N - 2) x (N - 2)`` matrix, and the residuals of all
held-out samples are ``Y - W X`` (computed in column blocks). It equals
rebuilding each split's model with
:func:`pipeline.modelling.pca_variants.build_albedo_parts` and projecting
(checked in the tests).

This module imports :mod:`albedo_model.errors`, :mod:`pipeline.modelling.generalisation`
and :mod:`pipeline.modelling.pca_variants`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from pipeline.modelling.generalisation import GramFold, gram_eigenpairs
from pipeline.modelling.pca_variants import VARIANTS, AlbedoParts, Variant, augment_with_mirror

__all__ = ["ResidualVariance", "attach_residual_variance", "loo_residual_variance",
           "residual_rms_per_channel"]

_BLOCK_COLUMNS = 16384


class ResidualVariance(NamedTuple):
    """Per-row leave-one-out residual variance of the albedo parts.

    Attributes
    ----------
    diffuse : (3n,) float64
        Per vertex and channel, interleaved (r0 g0 b0 r1 ...) like a PCAPart.
    specular : (3n,) float64 or None
        None when no specular maps were given.
    rank : int
        Rank of the split models (the smallest over the splits).
    n_held_out : int
        Held-out samples averaged (subjects, twice with symmetry augmentation).
    """

    diffuse: np.ndarray
    specular: np.ndarray | None
    rank: int
    n_held_out: int


def residual_rms_per_channel(residual_variance: np.ndarray) -> np.ndarray:
    """Root mean residual variance over vertices, per channel, (3,) (linear sRGB units)."""
    r = np.asarray(residual_variance, np.float64).reshape(-1, 3)
    return np.sqrt(r.mean(axis=0))


def _samples(maps: np.ndarray, symmetry: np.ndarray | None) -> np.ndarray:
    m = augment_with_mirror(maps, symmetry) if symmetry is not None else maps
    return m.reshape(len(m), -1)


def _fold_weights(coef: np.ndarray, fold: GramFold) -> np.ndarray:
    """Weights ``w`` over the training rows with ``fit = X_T^T w`` (mean included).

    The least-squares coefficients ``b`` of the centred held-out vector on the
    columns ``X_c^T coef`` give the centred fit ``X_c^T coef b``; adding the
    training mean and un-centring gives weights that sum to one.
    """
    n = coef.shape[0]
    if coef.shape[1] == 0:
        return np.full(n, 1.0 / n)
    normal = coef.T @ fold.gram @ coef
    b = np.linalg.lstsq(normal, coef.T @ fold.xy, rcond=1e-12)[0]
    a = coef @ b
    return a - a.mean() + 1.0 / n


def _basis(gram: np.ndarray, rank: int | None) -> np.ndarray:
    _, u = gram_eigenpairs(gram)
    return u if rank is None else u[:, :rank]


def _weights(gram_d: np.ndarray, gram_s: np.ndarray | None, n_sub: int, copies: int,
             variant: str, rank: int | None) -> tuple[np.ndarray, np.ndarray | None, int]:
    """Rows of held-out samples and the (H, N) fit weights of the diffuse and specular maps."""
    n_all = gram_d.shape[0]
    w_d = np.zeros((n_sub * copies, n_all))
    w_s = None if gram_s is None else np.zeros_like(w_d)
    used_rank = n_all
    for i in range(n_sub):
        train = np.array([j for j in range(n_all) if j % n_sub != i])
        for c in range(copies):
            held, row = i + c * n_sub, i * copies + c
            fd = GramFold(gram_d, train, held)
            fs = None if gram_s is None else GramFold(gram_s, train, held)
            joint = fs is not None and variant == "concatenated"
            coef = _basis(fd.gram + fs.gram if joint else fd.gram, rank)
            used_rank = min(used_rank, coef.shape[1])
            w_d[row, train] = _fold_weights(coef, fd)
            if fs is None:
                continue
            if variant == "independent":
                coef_s = _basis(fs.gram, rank)
                used_rank = min(used_rank, coef_s.shape[1])
                w_s[row, train] = _fold_weights(coef_s, fs)
            else:  # shared coefficients: the specular fit uses the diffuse fit's weights
                w_s[row, train] = w_d[row, train]
    return w_d, w_s, used_rank


def _held_rows(n_sub: int, copies: int) -> np.ndarray:
    return np.array([i + c * n_sub for i in range(n_sub) for c in range(copies)])


def _mean_squared_residual(x: np.ndarray, weights: np.ndarray, held: np.ndarray) -> np.ndarray:
    out = np.empty(x.shape[1])
    for start in range(0, x.shape[1], _BLOCK_COLUMNS):
        sl = slice(start, start + _BLOCK_COLUMNS)
        r = x[held, sl] - weights @ x[:, sl]
        out[sl] = np.mean(r * r, axis=0)
    return out


def loo_residual_variance(
    diffuse: np.ndarray,
    specular: np.ndarray | None,
    symmetry: np.ndarray | None,
    *,
    variant: Variant = "transferred",
    rank: int | None = None,
) -> ResidualVariance:
    """Leave-one-out per-row residual variance of the albedo PCA built from these maps.

    Parameters
    ----------
    diffuse : (S, n, 3) array
        Per-vertex diffuse albedo of S >= 3 subjects, linear sRGB.
    specular : (S, n, 3) array or None
        Specular albedo (None: a colour-only model; ``variant`` is then ignored).
    symmetry : (n,) int array or None
        Mirror partner of each vertex: the models are built with symmetry
        augmentation (as :func:`~pipeline.modelling.pca_variants.build_albedo_parts`)
        and both copies of a held-out subject are scored. ``None``: no augmentation.
    variant : {"independent", "concatenated", "transferred"}
        The model variant (see :mod:`pipeline.modelling.pca_variants`).
    rank : int, optional
        Rank of every split's model; the model's own rank (default: all a split allows).

    Returns
    -------
    ResidualVariance

    Raises
    ------
    InputError
        Fewer than 3 subjects, maps of different shapes, or an unknown variant.
    """
    d = np.asarray(diffuse, np.float64)
    if d.ndim != 3 or d.shape[2] != 3:
        raise InputError(f"diffuse maps must have shape (subjects, vertices, 3), got {d.shape}")
    if specular is not None and np.shape(specular) != d.shape:
        raise InputError(f"diffuse maps {d.shape} and specular maps {np.shape(specular)} differ")
    if d.shape[0] < 3:
        raise InputError(f"leave-one-out needs at least 3 subjects, got {d.shape[0]}")
    if variant not in VARIANTS:
        raise InputError(f"unknown albedo model variant {variant!r}")
    if rank is not None and rank < 0:
        raise InputError(f"rank must be non-negative, got {rank}")
    n_sub, copies = d.shape[0], 1 if symmetry is None else 2
    # a common shift of all samples changes no fit (weights sum to one): centring once
    # keeps the uncentred Gram matrices well conditioned
    xd = _samples(d, symmetry)
    xd = xd - xd.mean(axis=0)
    xs = None
    if specular is not None:
        xs = _samples(np.asarray(specular, np.float64), symmetry)
        xs = xs - xs.mean(axis=0)
    w_d, w_s, used = _weights(xd @ xd.T, None if xs is None else xs @ xs.T, n_sub, copies,
                              variant, rank)
    held = _held_rows(n_sub, copies)
    var_d = _mean_squared_residual(xd, w_d, held)
    var_s = None if xs is None else _mean_squared_residual(xs, w_s, held)
    return ResidualVariance(var_d, var_s, int(used), len(held))


def attach_residual_variance(parts: AlbedoParts, residual: ResidualVariance) -> AlbedoParts:
    """Return ``parts`` whose diffuse (and specular) PCA parts carry the residual variance."""
    diffuse = parts.diffuse.with_residual_variance(residual.diffuse)
    specular = parts.specular
    if residual.specular is not None:
        specular = specular.with_residual_variance(residual.specular)
    return parts._replace(diffuse=diffuse, specular=specular)
