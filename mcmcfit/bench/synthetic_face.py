"""A synthetic, BFM-sized morphable model for benchmarks: a bumpy half-ellipsoid "face".

The mesh is the front half of an ellipsoid (semi-axes 75 x 100 x 90 mm, x right,
y up, z towards the viewer) on a latitude/longitude grid, with a nose-like bump
and small ripples, so that ray casting, refits and normals see a realistic,
curved, open surface. The PCA parts have smooth random orthonormal bases (random
low-frequency Fourier fields over the grid, orthonormalised), with the ranks of
the real models: shape 50, expression 5, albedo 50 shared by diffuse and
specular. Deterministic for a seed; builds in about a second.

This module imports only :mod:`albedo_model.model` and :mod:`albedo_model.pca`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.model import MorphableModel
from albedo_model.pca import PCAPart

__all__ = ["synthetic_face_model", "FACE_SEMI_AXES_MM"]

#: Semi-axes (x, y, z) of the half ellipsoid, mm.
FACE_SEMI_AXES_MM = (75.0, 100.0, 90.0)


def _grid_mesh(n_lat: int, n_lon: int) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Vertices (n, 3) float64, triangles (m, 3) int32, grid coordinates ((n_lat,), (n_lon,))."""
    lat = np.linspace(-0.46 * np.pi, 0.46 * np.pi, n_lat)
    lon = np.linspace(-0.5 * np.pi, 0.5 * np.pi, n_lon)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    a, b, c = FACE_SEMI_AXES_MM
    unit = np.stack([np.cos(la) * np.sin(lo), np.sin(la), np.cos(la) * np.cos(lo)], -1)
    # a nose-like bump in front, plus ripples (about 1 mm) so that normals vary
    bump = 0.18 * np.exp(-((lo / 0.22) ** 2 + ((la + 0.05) / 0.35) ** 2))
    ripple = 0.012 * np.sin(9 * lo) * np.cos(7 * la)
    radial = 1.0 + bump + ripple
    verts = unit * radial[..., None] * np.array([a, b, c])
    idx = np.arange(n_lat * n_lon).reshape(n_lat, n_lon)
    q00, q01 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    q10, q11 = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    tris = np.empty((2 * q00.size, 3), np.int32)
    # counter-clockwise seen from +z (lon increases with x, lat with y)
    tris[0::2] = np.stack([q00, q01, q11], 1)
    tris[1::2] = np.stack([q00, q11, q10], 1)
    grid = (np.linspace(0.0, 1.0, n_lat), np.linspace(0.0, 1.0, n_lon))
    return verts.reshape(-1, 3), tris, grid


def _cosines(t: np.ndarray, g: int) -> np.ndarray:
    """(len(t), g) smooth 1-D basis ``cos(pi f t)``, f = 0..g-1, for t in [0, 1]."""
    return np.cos(np.pi * np.outer(t, np.arange(g)))


def _smooth_basis(rng: np.random.Generator, t_lat: np.ndarray, t_lon: np.ndarray, k: int,
                  g: int = 8) -> np.ndarray:
    """(3n, k) float64 orthonormal columns of smooth random fields (vertex-major, xyz minor).

    Each column is, per coordinate, a random combination of the separable
    low-frequency fields ``cos(pi f t_lat) cos(pi h t_lon)`` (f, h < g). The
    columns are orthonormalised in coefficient space with the Gram matrix of
    these fields, which costs nothing like a QR of the (3n, k) matrix.
    """
    bu, bv = _cosines(t_lat, g), _cosines(t_lon, g)
    decay = 1.0 / (1.0 + np.add.outer(np.arange(g), np.arange(g)))  # smoother is likelier
    coef = rng.standard_normal((3, g, g, k)) * decay[None, :, :, None]
    gram_1d = np.kron(bu.T @ bu, bv.T @ bv)  # (g*g, g*g): inner products of the 2-D fields
    flat = coef.reshape(3, g * g, k)
    gram = np.einsum("cak,ab,cbl->kl", flat, gram_1d, flat)
    chol = np.linalg.cholesky(gram)
    # columns R -> R L^-T, i.e. rows R^T -> L^-1 R^T: orthonormal under the Gram matrix
    flat = np.linalg.solve(chol, flat.transpose(2, 0, 1).reshape(k, -1)).reshape(k, 3, g, g)
    out = np.empty((len(t_lat), len(t_lon), 3, k))
    for c in range(3):
        out[:, :, c, :] = np.einsum("if,kfh,jh->ijk", bu, flat[:, c], bv, optimize=True)
    return out.reshape(-1, k)


def _part(rng: np.random.Generator, grid: tuple[np.ndarray, np.ndarray], mean: np.ndarray,
          k: int, rms_first: float) -> PCAPart:
    """PCA part whose first component moves the data by ``rms_first`` (rms) per entry."""
    basis = _smooth_basis(rng, *grid, k)
    std = rms_first * np.sqrt(mean.size) / (1.0 + np.arange(k)) ** 0.7
    return PCAPart(mean, basis, std**2)


def synthetic_face_model(seed: int = 0, n_lat: int = 232, n_lon: int = 232, *,
                         shape_rank: int = 50, expression_rank: int = 5,
                         albedo_rank: int = 50) -> MorphableModel:
    """Build a deterministic synthetic morphable model of BFM size.

    Parameters
    ----------
    seed : int
        Seed of the random bases.
    n_lat, n_lon : int
        Grid resolution; the default 232 x 232 gives 53,824 vertices and
        106,722 triangles (BFM 2017 face: 53,490 / 106,466).
    shape_rank, expression_rank, albedo_rank : int
        PCA ranks (albedo: shared by diffuse and specular).

    Returns
    -------
    MorphableModel
        Model frame in mm, x right, y up, the face looking along +z; diffuse and
        specular albedo in linear RGB with one shared coefficient vector.
    """
    rng = np.random.default_rng(seed)
    verts, tris, grid = _grid_mesh(n_lat, n_lon)
    shape = _part(rng, grid, verts.ravel(), shape_rank, 2.0)
    expression = _part(rng, grid, np.zeros(verts.size), expression_rank, 1.0)
    skin = np.array([0.55, 0.38, 0.30])
    t_lat, t_lon = np.meshgrid(*grid, indexing="ij")
    shade = (1.0 + 0.15 * np.cos(3 * np.pi * t_lat.reshape(-1, 1))
             * np.cos(2 * np.pi * t_lon.reshape(-1, 1)))
    diffuse = _part(rng, grid, (skin * shade).ravel(), albedo_rank, 0.04)
    specular = _part(rng, grid, np.full(verts.size, 0.15), albedo_rank, 0.02)
    return MorphableModel(
        verts, tris, shape, diffuse, expression=expression, specular=specular,
        shared_albedo=True, metadata={"description": "synthetic benchmark face", "seed": str(seed)},
    )
