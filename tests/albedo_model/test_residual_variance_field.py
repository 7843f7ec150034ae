"""The albedo parts' residual variance: a PCAPart field, kept by truncation, the crop and files."""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest
from momo_factory import assert_models_identical, random_part, synthetic_model

from albedo_model.errors import InputError
from albedo_model.io.momo_h5 import (
    RESIDUAL_PATH,
    AlbedoPart,
    read_albedo_part,
    read_model_h5,
    write_albedo_part,
    write_model_h5,
)
from albedo_model.model_crop import crop_model_with_maps, vertex_rows


def _with_residual(model, seed=5):
    """The model with float32 residual variances on its albedo parts."""
    rng = np.random.default_rng(seed)
    parts = {}
    for name in ("diffuse", "specular"):
        part = getattr(model, name)
        if part is not None:
            r = rng.uniform(1e-5, 4e-4, part.dim).astype(np.float32)
            parts[name] = part.with_residual_variance(r)
    return dataclasses.replace(model, **parts)


def test_field_is_validated_read_only_and_optional():
    rng = np.random.default_rng(0)
    part = random_part(rng, 12, 3)
    assert part.residual_variance is None
    with_r = part.with_residual_variance(np.full(12, 0.01))
    assert not with_r.residual_variance.flags.writeable
    np.testing.assert_allclose(with_r.marginal_std(include_residual=True) ** 2,
                               part.marginal_std() ** 2 + 0.01, rtol=1e-6)
    assert with_r.with_residual_variance(None).residual_variance is None
    for bad in (np.full(11, 0.01), np.full(12, -1.0), np.full(12, np.nan), np.ones(12, int)):
        with pytest.raises(InputError, match="residual"):
            part.with_residual_variance(bad)


def test_truncation_moves_the_dropped_modes_into_the_residual():
    rng = np.random.default_rng(1)
    part = random_part(rng, 30, 5).with_dtype(np.float64).with_residual_variance(np.full(30, 1e-3))
    small = part.truncate(2)
    # the residual plus the kept modes' variance is the full model's total, per row
    np.testing.assert_allclose(small.marginal_std(include_residual=True),
                               part.marginal_std(include_residual=True), rtol=1e-12)
    np.testing.assert_array_equal(part.truncate(5).residual_variance, part.residual_variance)
    assert part.with_dtype(np.float32).residual_variance.dtype == np.float32


@pytest.mark.parametrize("specular,shared", [(False, True), (True, True), (True, False)])
def test_model_with_residual_round_trips_through_the_file(tmp_path, specular, shared):
    model = _with_residual(synthetic_model(1, specular=specular, shared=shared))
    path = tmp_path / "m.h5"
    write_model_h5(model, path)
    back = read_model_h5(path)
    assert_models_identical(model, back)  # compares residual_variance bit for bit
    expected = {"color"} if not specular else {"diffuseAlbedo", "specularAlbedo"}
    with h5py.File(path, "r") as h5:
        assert set(h5[RESIDUAL_PATH]) == expected
        assert all(h5[f"{RESIDUAL_PATH}/{g}"].dtype == np.float32 for g in expected)
    res = back.albedo_residual_variance
    np.testing.assert_array_equal(res["diffuse"],
                                  model.diffuse.residual_variance.reshape(-1, 3))
    assert (res["specular"] is None) == (not specular)


def test_files_without_it_read_as_absent(tmp_path):
    model = synthetic_model(2)
    write_model_h5(model, tmp_path / "m.h5")
    back = read_model_h5(tmp_path / "m.h5")
    assert back.diffuse.residual_variance is None and back.specular.residual_variance is None
    with h5py.File(tmp_path / "m.h5", "r") as h5:
        assert RESIDUAL_PATH not in h5
    assert back.albedo_residual_variance == {"diffuse": None, "specular": None}


def test_albedo_part_file_keeps_it_and_a_bad_one_is_refused(tmp_path):
    model = _with_residual(synthetic_model(3))
    part = AlbedoPart(model.vertices, model.triangles, model.diffuse, model.specular,
                      dict(model.landmarks), {})
    write_albedo_part(part, tmp_path / "p.h5")
    back = read_albedo_part(tmp_path / "p.h5")
    np.testing.assert_array_equal(back.specular.residual_variance,
                                  model.specular.residual_variance)
    write_model_h5(model, tmp_path / "m.h5")
    with h5py.File(tmp_path / "m.h5", "r+") as h5:
        del h5[f"{RESIDUAL_PATH}/diffuseAlbedo"]
        h5[f"{RESIDUAL_PATH}/diffuseAlbedo"] = np.ones(5, np.float32)
    with pytest.raises(Exception, match="residual_variance"):
        read_model_h5(tmp_path / "m.h5")


@pytest.mark.parametrize("shared", [True, False])
def test_the_crop_keeps_the_rows_of_the_kept_vertices(tmp_path, shared):
    model = _with_residual(synthetic_model(4, shared=shared))
    keep = np.zeros(model.n_vertices, bool)
    keep[[0, 1, 2, 4, 5, 6, 8, 9, 10]] = True
    crop = crop_model_with_maps(model, keep, unpaired="forget")
    rows = vertex_rows(crop.vertex_index)
    for name in ("diffuse", "specular"):
        np.testing.assert_array_equal(getattr(crop.model, name).residual_variance,
                                      getattr(model, name).residual_variance[rows])
    assert crop.model.shape.residual_variance is None
    write_model_h5(crop.model, tmp_path / "crop.h5")
    assert_models_identical(read_model_h5(tmp_path / "crop.h5"), crop.model)
