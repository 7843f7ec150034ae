"""Derived region quantities: the vectorised region means against per-draw brute force."""

from __future__ import annotations

import numpy as np
import pytest
from face_factory import small_face_model

from albedo_model.errors import InputError
from mcmcfit.sampling.derived import (
    region_albedo_basis,
    region_albedo_means,
    region_albedo_series,
    vertex_areas,
)
from mcmcfit.sampling.param_vector import ParamLayout


@pytest.fixture(scope="module")
def model():
    return small_face_model()


def _random_regions(model, rng):
    labels = rng.integers(0, 4, model.n_vertices)
    return {f"r{i}": labels == i for i in range(3)}


def test_region_means_equal_brute_force_per_draw(model):
    rng = np.random.default_rng(0)
    regions = _random_regions(model, rng)
    basis = region_albedo_basis(model, regions)
    area = vertex_areas(model.shape_instance(), model.triangles)
    k = model.diffuse.rank
    coeffs = rng.normal(size=(2, 7, k))
    got = region_albedo_means(coeffs, basis)
    assert got.shape == (2, 7, 3, 3)
    for c, d in np.ndindex(2, 7):
        albedo = model.diffuse_instance(coeffs[c, d])  # (n, 3) linear
        for r, mask in enumerate(regions.values()):
            w = area[mask] / area[mask].sum()
            np.testing.assert_allclose(got[c, d, r], w @ albedo[mask], rtol=1e-10, atol=1e-12)
    # fewer coefficients than the rank: the missing ones are zero
    short = region_albedo_means(coeffs[..., :2], basis)
    padded = np.concatenate([coeffs[..., :2], np.zeros((2, 7, k - 2))], axis=-1)
    np.testing.assert_allclose(short, region_albedo_means(padded, basis), atol=1e-14)
    with pytest.raises(InputError):
        region_albedo_means(np.zeros(k + 1), basis)


def test_vertex_areas_add_up_to_the_mesh_area(model):
    v, t = model.shape_instance(), model.triangles
    total = 0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1)
    assert vertex_areas(v, t).sum() == pytest.approx(total.sum(), rel=1e-12)


def test_series_are_named_per_region_and_channel(model):
    rng = np.random.default_rng(1)
    basis = region_albedo_basis(model, _random_regions(model, rng))
    layout = ParamLayout(9, 4, model.diffuse.rank, 2)
    samples = rng.normal(size=(2, 5, layout.size))
    series = region_albedo_series(samples, layout, basis)
    assert list(series)[:4] == ["albedo_mean.r0.r", "albedo_mean.r0.g", "albedo_mean.r0.b",
                                "albedo_mean.r1.r"]
    assert len(series) == 9 and series["albedo_mean.r2.b"].shape == (2, 5)
    means = region_albedo_means(samples[..., layout.slice("albedo")], basis)
    np.testing.assert_array_equal(series["albedo_mean.r1.g"], means[:, :, 1, 1])


def test_a_model_without_landmarks_has_no_regions(model):
    import dataclasses

    bare = dataclasses.replace(model, landmarks={})
    basis = region_albedo_basis(bare)
    assert basis.regions == () and basis.names == ()
