"""Synthetic morphable models and exact-equality checks for the model-file tests."""

from __future__ import annotations

import numpy as np

from albedo_model.model import MorphableModel
from albedo_model.pca import PCAPart

PARTS = ("shape", "expression", "diffuse", "specular")


def grid_mesh(nx: int = 4, ny: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A planar grid: (nx*ny, 3) float32 vertices, int32 counter-clockwise triangles."""
    x, y = np.meshgrid(np.arange(nx, dtype=np.float32), np.arange(ny, dtype=np.float32))
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(nx * ny, np.float32)], 1) * 10
    tris = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a = j * nx + i
            tris += [(a, a + 1, a + nx + 1), (a, a + nx + 1, a + nx)]
    return verts, np.array(tris, np.int32)


def random_part(rng: np.random.Generator, d: int, k: int, noise: float = 0.1) -> PCAPart:
    """Random orthonormal float32 basis, descending float32 variances."""
    basis = np.linalg.qr(rng.standard_normal((d, k)))[0].astype(np.float32)
    variance = np.sort(rng.uniform(0.5, 4.0, k)).astype(np.float32)[::-1].copy()
    return PCAPart(rng.standard_normal(d).astype(np.float32), basis, variance, noise)


def synthetic_model(seed: int = 0, *, specular: bool = True, shared: bool = True) -> MorphableModel:
    """A 12-vertex model with every optional piece (expression, landmarks, symmetry, metadata).

    Arrays are float32 so that a file round trip is bit-exact; noise variances
    are float64 values that float32 cannot hold (0.1, 1e-3, 0.3).
    """
    rng = np.random.default_rng(seed)
    verts, tris = grid_mesh()
    d = verts.size
    n = len(verts)
    spec_rank = 4 if shared else 3
    return MorphableModel(
        vertices=verts, triangles=tris,
        shape=random_part(rng, d, 5), expression=random_part(rng, d, 3, noise=0.0),
        diffuse=random_part(rng, d, 4, noise=1e-3),
        specular=random_part(rng, d, spec_rank, noise=0.3) if specular else None,
        shared_albedo=shared,
        landmarks={"center.nose.tip": verts[5].astype(np.float64) + 1e-9,
                   "left.eye.corner_outer": np.array([0.1, 0.2, 1 / 3])},
        symmetry=np.arange(n)[::-1].copy(),
        metadata={"colour_space": "linear sRGB", "gamma": "2.2", "synthetic": "true"},
    )


def assert_parts_identical(
    a: PCAPart | None, b: PCAPart | None, *, exact_noise: bool = True
) -> None:
    assert (a is None) == (b is None)
    if a is None:
        return
    for name in ("mean", "basis", "variance"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y), name
    ra, rb = a.residual_variance, b.residual_variance
    assert (ra is None) == (rb is None), "residual_variance"
    if ra is not None:
        assert ra.dtype == rb.dtype and np.array_equal(ra, rb), "residual_variance"
    if exact_noise:
        assert a.noise_variance == b.noise_variance
    else:  # files written elsewhere keep only float32
        assert np.float32(a.noise_variance) == np.float32(b.noise_variance)


def assert_models_identical(a: MorphableModel, b: MorphableModel) -> None:
    assert a.vertices.dtype == b.vertices.dtype and np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.triangles, b.triangles)
    for name in PARTS:
        assert_parts_identical(getattr(a, name), getattr(b, name))
    assert a.shared_albedo == b.shared_albedo
    assert list(a.landmarks) == list(b.landmarks)
    for k in a.landmarks:
        assert np.array_equal(a.landmarks[k], b.landmarks[k])
    assert (a.symmetry is None) == (b.symmetry is None)
    if a.symmetry is not None:
        assert np.array_equal(a.symmetry, b.symmetry)
    assert a.metadata == b.metadata


def assert_orthonormal(part: PCAPart, tol: float = 1e-6) -> None:
    b = part.basis.astype(np.float64)
    assert np.abs(b.T @ b - np.eye(part.rank)).max() < tol
