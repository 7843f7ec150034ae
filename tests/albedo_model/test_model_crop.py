"""Cropping a model to a vertex subset: the exact marginal, topology, landmarks, symmetry, files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from momo_factory import assert_models_identical, assert_orthonormal, random_part

from albedo_model.errors import InputError
from albedo_model.io.momo_h5 import read_model_h5, write_model_h5
from albedo_model.model import MorphableModel
from albedo_model.model_crop import crop_model, crop_model_with_maps, vertex_rows


def _model(*, shared: bool = True, nx: int = 8, ny: int = 6, seed: int = 0) -> MorphableModel:
    """A grid model mirrored across its vertical mid-line, with every optional part."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(nx, dtype=np.float32), np.arange(ny, dtype=np.float32))
    verts = np.stack([x.ravel() - (nx - 1) / 2, y.ravel(), np.zeros(nx * ny, np.float32)], 1)
    verts = (verts * 10).astype(np.float32)
    tris = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a = j * nx + i
            tris += [(a, a + 1, a + nx + 1), (a, a + nx + 1, a + nx)]
    sym = (np.arange(nx * ny) // nx) * nx + (nx - 1 - np.arange(nx * ny) % nx)
    d = verts.size
    return MorphableModel(
        vertices=verts, triangles=np.array(tris, np.int32),
        shape=random_part(rng, d, 6), expression=random_part(rng, d, 3, noise=0.0),
        diffuse=random_part(rng, d, 5, noise=1e-3),
        specular=random_part(rng, d, 5 if shared else 4, noise=0.3), shared_albedo=shared,
        landmarks={"center.nose.tip": verts[3 * nx + 3].astype(np.float64),
                   "left.ear.top": verts[nx - 1].astype(np.float64),
                   "off.mesh": verts[2 * nx + 2].astype(np.float64) + (0.3, 0.2, 1.0)},
        symmetry=sym, metadata={"colour_space": "linear sRGB", "synthetic": "true"},
    )


def _inner(model: MorphableModel) -> np.ndarray:
    """A mirror-symmetric mask: the grid without its outer ring."""
    v = model.vertices
    return (np.abs(v[:, 0]) < v[:, 0].max() - 1) & (v[:, 1] > 1) & (v[:, 1] < v[:, 1].max() - 1)


@pytest.fixture(scope="module")
def model():
    return _model()


@pytest.fixture(scope="module")
def crop(model):
    return crop_model_with_maps(model, _inner(model), source="grid", region="inner")


def test_instances_are_the_full_instances_on_the_kept_vertices(model, crop):
    m, idx, maps = crop
    rng = np.random.default_rng(1)
    for _ in range(5):
        cs, ce, ca = (rng.standard_normal(model.ranks[k]) for k in ("shape", "expression",
                                                                     "diffuse"))
        full = model.shape_instance(cs, ce)[idx]
        np.testing.assert_allclose(
            m.shape_instance(maps["shape"] @ cs, maps["expression"] @ ce), full,
            rtol=0, atol=1e-5 * np.abs(full).max())
        # one coefficient vector still drives both albedo parts
        c = maps["albedo"] @ ca
        for got, want in ((m.diffuse_instance(c), model.diffuse_instance(ca)[idx]),
                          (m.specular_instance(c), model.specular_instance(ca)[idx])):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-5 * np.abs(want).max())


def test_covariances_are_the_marginal_including_the_albedo_cross_terms(model, crop):
    m, idx, _ = crop
    rows = vertex_rows(idx)

    def w(part, r=slice(None)):
        return part.scaled_basis.astype(np.float64)[r]

    for name in ("shape", "expression"):
        full, got = w(getattr(model, name), rows), w(getattr(m, name))
        np.testing.assert_allclose(got @ got.T, full @ full.T, atol=1e-5 * np.abs(full).max() ** 2)
    full = np.vstack([w(model.diffuse, rows), w(model.specular, rows)])
    got = np.vstack([w(m.diffuse), w(m.specular)])
    np.testing.assert_allclose(got @ got.T, full @ full.T, atol=1e-5 * np.abs(full).max() ** 2)


def test_bases_are_re_orthonormalised_and_the_maps_are_rotations(crop):
    m, _, maps = crop
    for name in ("shape", "expression", "diffuse"):
        assert_orthonormal(getattr(m, name), tol=1e-5)
    # the shared specular part: unit columns, variance = what each mode contributes
    np.testing.assert_allclose(np.linalg.norm(m.specular.basis.astype(float), axis=0), 1, atol=1e-6)
    for r in maps.values():
        np.testing.assert_allclose(r @ r.T, np.eye(len(r)), atol=1e-10)
        assert np.all(np.diag(r) > 0)
    assert set(maps) == {"shape", "expression", "albedo"}
    assert m.ranks == {"shape": 6, "expression": 3, "diffuse": 5, "specular": 5}


def test_keeping_every_vertex_gives_back_the_model(model):
    m, _, maps = crop_model_with_maps(model, np.ones(model.n_vertices, bool))
    for r in maps.values():
        np.testing.assert_allclose(r, np.eye(len(r)), atol=1e-5)
    for name in ("shape", "expression", "diffuse", "specular"):
        a, b = getattr(model, name), getattr(m, name)
        np.testing.assert_allclose(b.scaled_basis, a.scaled_basis, atol=1e-5)
        np.testing.assert_array_equal(b.mean, a.mean)
    np.testing.assert_array_equal(m.triangles, model.triangles)


def test_independent_albedo_gets_its_own_rotation():
    model = _model(shared=False)
    m, idx, maps = crop_model_with_maps(model, _inner(model))
    assert not m.shared_albedo and set(maps) == {"shape", "expression", "albedo", "specular"}
    cs = np.random.default_rng(2).standard_normal(model.specular.rank)
    want = model.specular_instance(None, cs)[idx]
    np.testing.assert_allclose(m.specular_instance(None, maps["specular"] @ cs), want, atol=1e-5)
    assert_orthonormal(m.specular, tol=1e-5)


def test_triangles_are_the_inside_ones_reindexed(model, crop):
    m, idx, _ = crop
    assert m.triangles.min() >= 0 and m.triangles.max() < m.n_vertices
    kept = np.zeros(model.n_vertices, bool)
    kept[idx] = True
    inside = model.triangles[np.all(kept[model.triangles], axis=1)]
    np.testing.assert_array_equal(idx[m.triangles], inside)
    np.testing.assert_array_equal(m.vertices, model.vertices[idx])
    assert np.all(np.diff(idx) > 0)


def test_landmarks_on_dropped_vertices_are_dropped(model, crop):
    m = crop.model
    assert set(m.landmarks) == {"center.nose.tip", "off.mesh"}  # off.mesh: nearest vertex kept
    assert m.landmark_vertices == {"center.nose.tip": int(np.flatnonzero(
        (m.vertices == model.vertices[3 * 8 + 3]).all(1))[0])}
    record = json.loads(m.metadata["crop"])
    assert record["landmarks_dropped"] == ["left.ear.top"]
    assert record["source"] == "grid" and record["region"] == "inner"
    assert record["vertices"] == [m.n_vertices, model.n_vertices]
    assert m.metadata["synthetic"] == "true"


def test_symmetry_map_is_the_full_map_restricted(model, crop):
    m, idx, _ = crop
    assert m.symmetry is not None
    np.testing.assert_array_equal(idx[m.symmetry], model.symmetry[idx])
    np.testing.assert_array_equal(m.symmetry[m.symmetry], np.arange(m.n_vertices))


def test_vertices_whose_mirror_is_dropped(model):
    one_sided = _inner(model) & (model.vertices[:, 0] > -15)
    lonely = one_sided & ~one_sided[model.symmetry]
    assert lonely.any()
    dropped = crop_model_with_maps(model, one_sided)  # default: drop them as well
    assert dropped.vertex_index.size == (one_sided & ~lonely).sum()
    np.testing.assert_array_equal(dropped.vertex_index[dropped.model.symmetry],
                                  model.symmetry[dropped.vertex_index])
    forgot = crop_model(model, one_sided, unpaired="forget")
    assert forgot.symmetry is None and forgot.n_vertices == one_sided.sum()
    with pytest.raises(InputError, match="mirror"):
        crop_model(model, one_sided, unpaired="error")


def test_the_crop_round_trips_through_the_albedomm_file(tmp_path, crop):
    path = tmp_path / "crop.h5"
    write_model_h5(crop.model, path, layout="albedomm")
    assert_models_identical(read_model_h5(path), crop.model)


@pytest.mark.parametrize("keep, message", [
    (np.zeros(48, bool), "no vertex"),
    (np.ones(5, bool), "shape"),
    (np.array([3]), "too few"),
    (np.array([0, 99]), "out of range"),
])
def test_bad_selections_are_refused(model, keep, message):
    with pytest.raises(InputError, match=message):
        crop_model(model, keep, unpaired="forget")
