"""UV atlases: xatlas charts that do not overlap, validation, crops and the model file."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh
from momo_factory import synthetic_model

from albedo_model.errors import FormatError, InputError
from albedo_model.io.momo_h5 import UV_PATH, read_model_h5, write_model_h5
from albedo_model.model_crop import crop_model
from albedo_model.texture.bake import bake_vertex_values
from albedo_model.uv_atlas import UVAtlas, compute_uv_atlas, uv_vertices

pytest.importorskip("xatlas")


@pytest.fixture(scope="module")
def sphere():
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=50.0)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def _areas(uv: np.ndarray, tri: np.ndarray) -> np.ndarray:
    a, b, c = uv[tri[:, 0]], uv[tri[:, 1]], uv[tri[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def test_a_closed_surface_is_cut_into_charts_that_do_not_overlap(sphere):
    v, t = sphere
    atlas = compute_uv_atlas(v, t)
    atlas.check_mesh(t, len(v))
    owner = uv_vertices(atlas, t)
    assert atlas.n_points > len(v)  # a sphere cannot be flattened without seams
    assert np.array_equal(np.unique(owner), np.arange(len(v)))
    areas = _areas(atlas.uv, atlas.uv_triangles)
    assert np.all(np.abs(areas) > 0), "a triangle was flattened to nothing"
    # Overlapping charts would cover less than their summed area: count the texels whose
    # centres lie in a triangle (the baker's ray cast) against the summed areas.
    size = 512
    baked = bake_vertex_values(atlas, t, np.ones(len(v)), size)
    inside = _areas(baked.atlas.uv, baked.atlas.uv_triangles)
    assert baked.covered.mean() == pytest.approx(np.abs(inside).sum(), rel=0.03)
    # near-conformal: 3D and UV areas of the triangles are proportional within each chart
    # (xatlas scales every chart alike), so the spread of the ratio stays small
    a3 = 0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1)
    ratio = np.abs(areas) / a3
    assert np.percentile(ratio, 95) / np.percentile(ratio, 5) < 3.0


def test_the_atlas_is_deterministic(sphere):
    v, t = sphere
    a, b = compute_uv_atlas(v, t), compute_uv_atlas(v, t)
    assert np.array_equal(a.uv, b.uv) and np.array_equal(a.uv_triangles, b.uv_triangles)


@pytest.mark.parametrize(("uv", "tri", "message"), [
    (np.zeros((3, 3)), [[0, 1, 2]], "shape"),
    ([[0, 0], [1, 0], [0, 1.5]], [[0, 1, 2]], r"\[0, 1\]"),
    ([[0, 0], [1, 0], [np.nan, 1]], [[0, 1, 2]], "finite"),
    ([[0, 0], [1, 0], [0, 1]], [[0, 1, 3]], "out of range"),
    ([[0, 0], [1, 0], [0, 1]], [[0.0, 1.0, 2.0]], "integer"),
])
def test_bad_atlases_are_refused(uv, tri, message):
    with pytest.raises(InputError, match=message):
        UVAtlas(np.asarray(uv, float), np.asarray(tri))


def test_an_atlas_must_fit_its_mesh():
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    shared = UVAtlas([[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 1, 2], [0, 2, 1]])  # point 1: two vertices
    with pytest.raises(InputError, match="shared by two mesh vertices"):
        shared.check_mesh(tri, 4)
    with pytest.raises(InputError, match="1 triangles, the mesh 2"):
        UVAtlas([[0, 0], [1, 0], [1, 1]], [[0, 1, 2]]).check_mesh(tri, 4)


def test_model_file_keeps_the_atlas_and_crops_restrict_it(tmp_path):
    model = synthetic_model()
    atlas = compute_uv_atlas(model.vertices, model.triangles)
    with_uv = dataclasses.replace(model, uv_atlas=atlas)
    path = tmp_path / "m.h5"
    write_model_h5(with_uv, path)
    back = read_model_h5(path)
    assert np.array_equal(back.uv_atlas.uv, atlas.uv.astype(np.float32))
    assert np.array_equal(back.uv_atlas.uv_triangles, atlas.uv_triangles)
    assert read_model_h5(_without_uv(path, tmp_path)).uv_atlas is None

    keep = model.vertices[:, 0] > np.median(model.vertices[:, 0])
    cropped = crop_model(with_uv, keep, unpaired="forget")
    kept_tri = np.all(keep[model.triangles], axis=1)
    # every kept triangle keeps its texture corners
    assert np.array_equal(cropped.uv_atlas.uv[cropped.uv_atlas.uv_triangles],
                          atlas.uv[atlas.uv_triangles[kept_tri]])


def _without_uv(path, tmp_path):
    import shutil

    import h5py

    copy = tmp_path / "no-uv.h5"
    shutil.copy(path, copy)
    with h5py.File(copy, "a") as h5:
        del h5[UV_PATH]
    return copy


def test_a_broken_atlas_in_a_file_names_the_file(tmp_path):
    import h5py

    model = synthetic_model()
    atlas = compute_uv_atlas(model.vertices, model.triangles)
    path = tmp_path / "m.h5"
    write_model_h5(dataclasses.replace(model, uv_atlas=atlas), path)
    with h5py.File(path, "a") as h5:
        h5[f"{UV_PATH}/triangles"][0, 0] = atlas.n_points + 5
    with pytest.raises(FormatError, match="m.h5.*out of range"):
        read_model_h5(path)
