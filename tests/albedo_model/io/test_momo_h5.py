"""MoMo / AlbedoMM HDF5 reading and writing (albedo_model.io.momo_h5, hdf5_layout)."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from momo_factory import (
    assert_models_identical,
    assert_orthonormal,
    assert_parts_identical,
    synthetic_model,
)

from albedo_model.errors import FormatError, InputError
from albedo_model.io import hdf5_layout, momo_h5
from albedo_model.io.momo_h5 import (
    AlbedoPart,
    read_albedo_part,
    read_model_h5,
    write_albedo_part,
    write_model_h5,
)
from albedo_model.pca import PCAPart

# -- the scalismo fixtures ----------------------------------------------------

def test_random_momo_fixture(shared_data: Path) -> None:
    path = shared_data / "scalismo" / "random-momo.h5"
    model = read_model_h5(path)
    assert (model.n_vertices, model.n_triangles) == (25, 32)
    assert model.ranks == {"shape": 10, "expression": 10, "diffuse": 10}
    assert model.specular is None
    with h5py.File(path, "r") as h5:
        points = h5["shape/representer/points"][()].T
        cells = h5["shape/representer/cells"][()].T
        color_mean = h5["color/model/mean"][()]
    assert np.array_equal(model.vertices, points) and np.array_equal(model.triangles, cells)
    for name in ("shape", "expression", "diffuse"):
        assert_orthonormal(getattr(model, name))
        part = getattr(model, name)
        assert np.array_equal(part.instance(np.zeros(part.rank)), part.mean.astype(np.float64))
    assert np.array_equal(model.diffuse_instance().ravel(), color_mean.astype(np.float64))
    flat = model.shape.mean.astype(np.float64) + model.expression.mean
    assert np.allclose(model.shape_instance().ravel(), flat, rtol=0, atol=1e-12)
    assert list(model.landmarks) == ["69hsGX0vL4", "zUAfXHdZyU", "xSW8ywne0O", "4aXbBvmcfl",
                                     "0s2kuFNgfT"]
    assert model.landmarks["69hsGX0vL4"].tolist() == [
        1.9334313325395973, 3.7067336908397888, -0.019227423549439977]
    # every landmark is a reference vertex (exactly, at float32 precision)
    for name, p in model.landmarks.items():
        hits = np.flatnonzero((points == p.astype(np.float32)).all(1))
        assert hits.size == 1 and model.landmark_vertices[name] == hits[0]
    assert model.metadata["colour_space"] == "RGB"


def test_random_l4_fixture(shared_data: Path) -> None:
    path = shared_data / "scalismo" / "random-l4.h5"
    model = read_model_h5(path)
    assert (model.n_vertices, model.n_triangles) == (1529, 3044)
    assert model.ranks == {"shape": 19, "diffuse": 19}
    with h5py.File(path, "r") as h5:
        raw_cells = h5["shape/representer/cells"][()]
        points = h5["shape/representer/points"][()].T
    assert raw_cells.dtype == np.uint32
    assert model.triangles.dtype == np.int32 and np.array_equal(model.triangles, raw_cells.T)
    # the model's vertices are the representer points, not the shape mean
    assert np.array_equal(model.vertices, points)
    assert np.abs(model.shape.mean.reshape(-1, 3) - points).max() > 1.0
    assert_orthonormal(model.shape)
    assert_orthonormal(model.diffuse)
    assert np.array_equal(model.shape.instance(np.zeros(19)), model.shape.mean.astype(np.float64))
    assert len(model.landmarks) == 60
    assert np.allclose(model.landmarks["center.nose.tip"], [0.203733876, 0.97169292, 131.823807],
                       rtol=0, atol=1e-12)
    assert {"center.chin.tip", "left.eye.corner_outer", "right.lips.corner"} <= set(model.landmarks)
    assert len(model.landmark_vertices) == 60
    for name, p in model.landmarks.items():
        hits = np.flatnonzero((points == p.astype(np.float32)).all(1))
        assert model.landmark_vertices[name] in hits
    # upper and lower inner lip share one vertex in this low-resolution head
    assert (model.landmark_vertices["center.lips.lower.inner"]
            == model.landmark_vertices["center.lips.upper.inner"])
    assert model.shape.noise_variance == pytest.approx(0.01234, rel=1e-6)


@pytest.mark.parametrize("name", ["random-momo.h5", "random-l4.h5"])
def test_fixture_round_trip(shared_data: Path, tmp_path: Path, name: str) -> None:
    model = read_model_h5(shared_data / "scalismo" / name)
    write_model_h5(model, tmp_path / "out.h5")
    assert_models_identical(model, read_model_h5(tmp_path / "out.h5"))


# -- round trips of synthetic models ------------------------------------------

@pytest.mark.parametrize("specular,shared", [(False, True), (True, True), (True, False)])
def test_round_trip_exact(tmp_path: Path, specular: bool, shared: bool) -> None:
    model = synthetic_model(1, specular=specular, shared=shared)
    write_model_h5(model, tmp_path / "m.h5")
    back = read_model_h5(tmp_path / "m.h5")
    assert_models_identical(model, back)
    with h5py.File(tmp_path / "m.h5", "r") as h5:
        assert ("color" in h5) == (not specular)
        assert ("diffuseAlbedo" in h5) == specular


def test_written_layout_is_scalismo_0_9(tmp_path: Path) -> None:
    model = synthetic_model(2)
    write_model_h5(model, tmp_path / "m.h5")
    n, m = model.n_vertices, model.n_triangles
    with h5py.File(tmp_path / "m.h5", "r") as h5:
        for g in ("", "shape/", "diffuseAlbedo/", "specularAlbedo/", "expression/"):
            assert h5[f"{g}version/majorVersion"].dtype == np.int32
            assert h5[f"{g}version/majorVersion"].shape == ()
            assert h5[f"{g}version/minorVersion"][()] == 9
        assert h5["catalog/MorphableModel/modelType"][()].tolist() == [b"CUSTOM_MODEL"]
        assert h5["catalog/MorphableModel.shape/modelType"][()].tolist() == [b"POLYGON_MESH_MODEL"]
        for g in ("diffuseAlbedo", "specularAlbedo", "expression"):
            entry = h5[f"catalog/MorphableModel.{g}"]
            assert entry["modelType"][()].tolist() == [b"POLYGON_MESH_DATA_MODEL"]
            assert entry["modelPath"][()].tolist() == [f"/{g}".encode()]
        for g, k in (("shape", 5), ("diffuseAlbedo", 4), ("specularAlbedo", 4), ("expression", 3)):
            mod = h5[f"{g}/model"]
            assert mod["mean"].dtype == np.float32 and mod["mean"].shape == (3 * n,)
            assert mod["pcaBasis"].dtype == np.float32 and mod["pcaBasis"].shape == (3 * n, k)
            assert mod["pcaVariance"].dtype == np.float32 and mod["pcaVariance"].shape == (k,)
            assert mod["noiseVariance"].dtype == np.float32 and mod["noiseVariance"].shape == (1,)
            assert h5[f"{g}/modelinfo/build-time"].shape == (1,)
            rep = h5[f"{g}/representer"]
            assert rep["points"].dtype == np.float32 and rep["points"].shape == (3, n)
            assert rep["cells"].dtype == np.int32 and rep["cells"].shape == (3, m)
            assert np.array_equal(rep["points"][0], model.vertices[:, 0])  # row 0 = every x
            assert rep.attrs["datasetType"].tolist() == [b"POLYGON_MESH"]
            assert rep.attrs["name"][0] == hdf5_layout.REPRESENTER_NAMES[g].encode()
        cs = h5["diffuseAlbedo/representer/colorspace"]
        assert cs.shape == (1,) and cs.dtype.itemsize == 4 and cs[0] == b"RGB"  # "RGB\0"
        lm = h5["metadata/landmarks/json"]
        assert lm.shape == (1,) and lm.dtype.kind == "S"
        items = json.loads(lm[0])
        assert [i["id"] for i in items] == list(model.landmarks)
        assert h5["metadata/mcmcfit/symmetry"].dtype == np.int32
        info = json.loads(h5["metadata/mcmcfit/info"][0])
        assert info["metadata"] == model.metadata and info["shared_albedo"] is True


def test_albedo_part_round_trip(tmp_path: Path) -> None:
    model = synthetic_model(3)
    part = AlbedoPart(model.vertices, model.triangles, model.diffuse, model.specular,
                      dict(model.landmarks), {"colour_space": "linear sRGB"})
    for placeholder in (True, False):
        path = tmp_path / f"part{placeholder}.h5"
        write_albedo_part(part, path, shape_placeholder=placeholder)
        back = read_albedo_part(path)
        assert np.array_equal(back.vertices, part.vertices)
        assert np.array_equal(back.triangles, part.triangles)
        assert_parts_identical(back.diffuse, part.diffuse)
        assert_parts_identical(back.specular, part.specular)
        assert list(back.landmarks) == list(part.landmarks)
        assert all(np.array_equal(back.landmarks[k], part.landmarks[k]) for k in part.landmarks)
        assert back.metadata == part.metadata
        with h5py.File(path, "r") as h5:
            assert ("shape" in h5) == placeholder
        with pytest.raises(FormatError, match="albedo part"):
            read_model_h5(path)


def write_release_like_albedo_part(path: Path, part: AlbedoPart) -> None:
    """What AlbedoMM's release files hold: a dummy rank-1 shape over 75 values, no mcmcfit info."""
    with h5py.File(path, "w") as h5:
        hdf5_layout.write_version(h5)
        rng = np.random.default_rng(9)
        dummy = PCAPart(rng.standard_normal(75).astype(np.float32),
                        np.eye(75, 1, dtype=np.float32), np.ones(1, np.float32))
        for group, p in (("shape", dummy), ("diffuseAlbedo", part.diffuse),
                         ("specularAlbedo", part.specular)):
            hdf5_layout.write_pca_group(h5, group, p, part.vertices, part.triangles,
                                        colorspace=group != "shape")
        hdf5_layout.write_text(h5.create_group("metadata/landmarks"), "json",
                               hdf5_layout.landmarks_to_json(part.landmarks))


def test_release_like_albedo_part(tmp_path: Path) -> None:
    model = synthetic_model(4)
    part = AlbedoPart(model.vertices, model.triangles, model.diffuse, model.specular, {}, {})
    write_release_like_albedo_part(tmp_path / "release.h5", part)
    back = read_albedo_part(tmp_path / "release.h5")
    assert_parts_identical(back.diffuse, part.diffuse, exact_noise=False)
    assert_parts_identical(back.specular, part.specular, exact_noise=False)
    assert back.metadata["colour_space"] == "linear sRGB"
    with pytest.raises(FormatError, match="release.h5: an AlbedoMM albedo part"):
        read_model_h5(tmp_path / "release.h5")


def test_legacy_v08_scaled_columns(tmp_path: Path) -> None:
    model = synthetic_model(5, specular=False)
    path = tmp_path / "v08.h5"
    write_model_h5(model, path)
    with h5py.File(path, "r+") as h5:
        for g in ("shape", "color", "expression"):
            var = h5[f"{g}/model/pcaVariance"][()].astype(np.float64)
            h5[f"{g}/model/pcaBasis"][...] = h5[f"{g}/model/pcaBasis"][()] * np.sqrt(var)
            h5[f"{g}/version/minorVersion"][...] = 8
        h5["version/minorVersion"][...] = 8
    back = read_model_h5(path)
    for name in ("shape", "diffuse", "expression"):
        part, orig = getattr(back, name), getattr(model, name)
        assert_orthonormal(part)
        assert np.array_equal(part.variance, orig.variance)
        assert np.allclose(part.basis, orig.basis, rtol=0, atol=1e-6)
        c = np.linspace(-1, 1, part.rank)
        assert np.allclose(part.instance(c), orig.instance(c), rtol=0, atol=1e-5)


def test_missing_part_version_means_0_8(tmp_path: Path) -> None:
    model = synthetic_model(6, specular=False)
    write_model_h5(model, tmp_path / "m.h5")
    with h5py.File(tmp_path / "m.h5", "r+") as h5:
        var = h5["shape/model/pcaVariance"][()]
        h5["shape/model/pcaBasis"][...] = h5["shape/model/pcaBasis"][()] * np.sqrt(var)
        del h5["shape/version"], h5["color/version"]
    back = read_model_h5(tmp_path / "m.h5")
    assert_orthonormal(back.shape)
    assert np.allclose(back.shape.basis, model.shape.basis, rtol=0, atol=1e-6)
    # an unversioned part whose columns are already orthonormal is read bit-exactly
    assert_parts_identical(back.diffuse, model.diffuse)


def test_tlms_text_landmarks_and_scalar_strings(tmp_path: Path) -> None:
    model = synthetic_model(7, specular=False)
    path = tmp_path / "m.h5"
    write_model_h5(model, path)
    with h5py.File(path, "r+") as h5:
        del h5["metadata/landmarks/json"], h5["metadata/mcmcfit"]
        h5["metadata/landmarks/text"] = np.bytes_(
            b"center.nose.tip 1 1.5 -2 3e1\n\nleft.eye.corner_outer 0 0.25 0.5 0.75\n")
        del h5["catalog/MorphableModel/modelType"]
        h5["catalog/MorphableModel/modelType"] = np.bytes_(b"CUSTOM_MODEL\0")
    back = read_model_h5(path)
    assert back.landmarks["center.nose.tip"].tolist() == [1.5, -2.0, 30.0]
    assert back.landmarks["left.eye.corner_outer"].tolist() == [0.25, 0.5, 0.75]
    assert back.symmetry is None and back.metadata["source_format"] == "scalismo MoMo HDF5"


def test_failed_write_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    model = synthetic_model(8)
    with pytest.raises(InputError):
        write_model_h5(model, tmp_path / "m.h5", layout="momo")

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(momo_h5, "write_pca_group", broken)
    with pytest.raises(OSError):
        write_model_h5(model, tmp_path / "m.h5")
    assert list(tmp_path.iterdir()) == []


# -- bad input ----------------------------------------------------------------

def _edit(path: Path, how: str) -> None:
    if how == "truncated":
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif how == "not-hdf5":
        path.write_text("this is not an HDF5 file\n")
    else:
        with h5py.File(path, "r+") as h5:
            if how == "missing-dataset":
                del h5["shape/model/pcaBasis"]
            elif how == "wrong-shape":
                del h5["color/model/mean"]
                h5["color/model/mean"] = np.zeros(7, np.float32)
            elif how == "nan":
                b = h5["shape/model/pcaBasis"]
                b[3, 1] = np.nan
            elif how == "bad-cells":
                c = h5["shape/representer/cells"]
                c[0, 0] = 10_000
            elif how == "representer-mismatch":
                p = h5["color/representer/points"]
                p[0, 0] += 1
            elif how == "bad-landmarks":
                del h5["metadata/landmarks/json"]
                hdf5_layout.write_text(h5["metadata/landmarks"], "json", '[{"id": 3}]')
            elif how == "bad-tlms":
                del h5["metadata/landmarks/json"]
                hdf5_layout.write_text(h5["metadata/landmarks"], "text", "nose 1 2.0 3.0\n")


BAD = {
    "truncated": "not a readable HDF5 file",
    "not-hdf5": "not a readable HDF5 file",
    "missing-dataset": "missing dataset /shape/model/pcaBasis",
    "wrong-shape": "/color/model/mean has shape",
    "nan": "NaN",
    "bad-cells": "cells index outside",
    "representer-mismatch": "representer differs",
    "bad-landmarks": "landmark 0",
    "bad-tlms": "landmark text: line 1",
}


@pytest.mark.parametrize("how", sorted(BAD))
def test_bad_input_raises_format_error(tmp_path: Path, how: str) -> None:
    path = tmp_path / f"bad-{how}.h5"
    write_model_h5(synthetic_model(10, specular=False), path)
    _edit(path, how)
    with pytest.raises(FormatError) as err:
        read_model_h5(path)
    message = str(err.value)
    assert str(path) in message and BAD[how] in message and "\n" not in message


def test_missing_file_is_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="nothere.h5: file not found"):
        read_model_h5(tmp_path / "nothere.h5")
