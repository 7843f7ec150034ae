"""``mcmcfit model info`` and ``mcmcfit model combine`` (mcmcfit.commands.model)."""

from __future__ import annotations

import hashlib
import json
import pickle
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from albedo_model.io.model_files import load_model
from albedo_model.io.momo_h5 import AlbedoPart, read_albedo_part, write_albedo_part
from albedo_model.pca import PCAPart
from mcmcfit.cli import main

NX, NY = 5, 4  # grid mesh: 20 vertices, 24 triangles


def grid(nx: int = NX, ny: int = NY) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.meshgrid(np.arange(nx, dtype=np.float32), np.arange(ny, dtype=np.float32))
    verts = np.stack([x.ravel(), y.ravel(), (x * y).ravel() / 10], 1).astype(np.float32)
    tris = [(j * nx + i, j * nx + i + 1, (j + 1) * nx + i + 1) for j in range(ny - 1)
            for i in range(nx - 1)]
    tris += [(j * nx + i, (j + 1) * nx + i + 1, (j + 1) * nx + i) for j in range(ny - 1)
             for i in range(nx - 1)]
    return verts, np.array(tris, np.int32)


def orthonormal(rng: np.random.Generator, d: int, k: int) -> np.ndarray:
    return np.linalg.qr(rng.standard_normal((d, k)))[0].astype(np.float32)


def write_bfm2017_like(path: Path, seed: int = 0, nx: int = NX) -> dict:
    """A BFM-2017-layout file written with raw h5py, independent of the project's writer."""
    rng = np.random.default_rng(seed)
    verts, tris = grid(nx)
    d = verts.size
    truth = {"vertices": verts, "triangles": tris}

    def s(text: str) -> np.ndarray:
        return np.array([text.encode()], dtype=f"S{len(text)}")

    with h5py.File(path, "w") as h5:
        h5["version/majorVersion"] = np.int32(0)
        h5["version/minorVersion"] = np.int32(9)
        h5["catalog/MorphableModel/modelPath"] = s("/")
        h5["catalog/MorphableModel/modelType"] = s("CUSTOM_MODEL")
        for group, name, k in (("shape", "Shape", 6), ("color", "Color", 5),
                               ("expression", "Expression", 3)):
            mean = rng.standard_normal(d).astype(np.float32)
            basis = orthonormal(rng, d, k)
            var = rng.uniform(1, 9, k).astype(np.float32)
            truth[group] = (mean, basis, var)
            g = h5.create_group(group)
            g["version/majorVersion"] = np.int32(0)
            g["version/minorVersion"] = np.int32(9)
            g["model/mean"], g["model/pcaBasis"], g["model/pcaVariance"] = mean, basis, var
            g["model/noiseVariance"] = np.array([0.5], np.float32)
            g["modelinfo/build-time"] = s("Mon Mar 13 16:18:11 CET 2017")
            rep = g.create_group("representer")
            rep.attrs["name"] = np.array([f"gravis::Mesh{name}Representer".encode()])
            rep.attrs["datasetType"] = np.array([b"POLYGON_MESH"])
            rep["points"] = verts.T.copy()
            rep["cells"] = tris.T.copy()
            if group == "color":
                rep["colorspace"] = np.array([b"RGB\0"], dtype="S4")
        lms = [{"id": "center.nose.tip", "coordinates": verts[7].astype(float).tolist()},
               {"id": "left.eye.corner_outer", "coordinates": [1.0, 2.5, 0.125]}]
        truth["landmarks"] = {lm["id"]: lm["coordinates"] for lm in lms}
        h5["metadata/landmarks/json"] = s(json.dumps(lms))
    return truth


def albedo_part(seed: int = 1, nx: int = NX, flip: bool = False) -> AlbedoPart:
    rng = np.random.default_rng(seed)
    verts, tris = grid(nx)
    if flip:
        tris[0] = tris[0, ::-1]
    d = verts.size

    def part() -> PCAPart:
        return PCAPart(rng.uniform(0, 1, d).astype(np.float32), orthonormal(rng, d, 4),
                       np.array([0.04, 0.02, 0.01, 0.005], np.float32), 1e-4)

    return AlbedoPart(verts, tris, part(), part(), {}, {"colour_space": "linear sRGB"})


def one_line(text: str) -> str:
    lines = text.strip().splitlines()
    assert len(lines) == 1, text
    return lines[0]


# -- model info ---------------------------------------------------------------

def test_info_json_random_l4(shared_data: Path, capsys: pytest.CaptureFixture) -> None:
    path = shared_data / "scalismo" / "random-l4.h5"
    assert main(["model", "info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["vertices"] == 1529 and info["triangles"] == 3044
    assert info["parts"] == {"shape": 19, "diffuse": 19}
    assert len(info["landmarks"]) == 60 and "center.nose.tip" in info["landmarks"]
    assert info["landmarks_on_vertices"] == 60
    assert info["path"] == str(path)
    assert info["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert info["colour_space"] == "RGB"


def test_info_text(shared_data: Path, capsys: pytest.CaptureFixture) -> None:
    path = shared_data / "scalismo" / "random-momo.h5"
    assert main(["model", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "vertices:      25" in out and "triangles:     32" in out
    assert "shape 10, expression 10, diffuse 10" in out and "69hsGX0vL4" in out


def test_info_albedo_part_and_flame(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    write_albedo_part(albedo_part(), tmp_path / "part.h5")
    assert main(["model", "info", str(tmp_path / "part.h5"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["parts"] == {"diffuse": 4, "specular": 4} and info["vertices"] == NX * NY
    rng = np.random.default_rng(0)
    np.savez(tmp_path / "flame.npz", MU=rng.uniform(size=(4, 4, 3)),
             PC=rng.standard_normal((4, 4, 3, 2)))
    assert main(["model", "info", str(tmp_path / "flame.npz"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["parts"] == {"diffuse": 2} and info["texture_shape"] == [4, 4, 3]


# -- model combine ------------------------------------------------------------

def test_combine_round_trip(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    truth = write_bfm2017_like(tmp_path / "model2017-1_face12_nomouth.h5")
    part = albedo_part()
    write_albedo_part(part, tmp_path / "albedoModel2020_face12_albedoPart.h5")
    out = tmp_path / "joint.h5"
    rc = main(["model", "combine", "--shape", str(tmp_path / "model2017-1_face12_nomouth.h5"),
               "--albedo", str(tmp_path / "albedoModel2020_face12_albedoPart.h5"), "-o", str(out)])
    assert rc == 0, capsys.readouterr().err
    joint = load_model(out)
    assert np.array_equal(joint.vertices, truth["vertices"])
    assert np.array_equal(joint.triangles, truth["triangles"])
    for name, group in (("shape", "shape"), ("expression", "expression")):
        got = getattr(joint, name)
        for a, b in zip((got.mean, got.basis, got.variance), truth[group], strict=True):
            assert a.dtype == np.float32 and np.array_equal(a, b)
    for name in ("diffuse", "specular"):
        got, want = getattr(joint, name), getattr(part, name)
        assert np.array_equal(got.mean, want.mean) and np.array_equal(got.basis, want.basis)
        assert np.array_equal(got.variance, want.variance)
        assert got.noise_variance == want.noise_variance
    assert joint.shared_albedo
    assert {k: v.tolist() for k, v in joint.landmarks.items()} == truth["landmarks"]
    assert joint.landmark_vertices == {"center.nose.tip": 7}
    assert joint.metadata["colour_space"] == "linear sRGB"
    assert joint.metadata["albedo_source"] == "albedoModel2020_face12_albedoPart.h5"
    # its albedo half reads back as the albedo part that went in
    again = read_albedo_part(out)
    assert np.array_equal(again.diffuse.basis, part.diffuse.basis)
    with h5py.File(out, "r") as h5:
        assert {"shape", "expression", "diffuseAlbedo", "specularAlbedo"} <= set(h5)
        assert "color" not in h5
    assert "joint.h5" in capsys.readouterr().out


@pytest.mark.parametrize("mismatch", ["vertex-count", "cells"])
def test_combine_topology_mismatch(
    tmp_path: Path, capsys: pytest.CaptureFixture, mismatch: str
) -> None:
    write_bfm2017_like(tmp_path / "bfm.h5")
    part = albedo_part(nx=NX + 1) if mismatch == "vertex-count" else albedo_part(flip=True)
    write_albedo_part(part, tmp_path / "part.h5")
    out = tmp_path / "joint.h5"
    rc = main(["model", "combine", "--shape", str(tmp_path / "bfm.h5"),
               "--albedo", str(tmp_path / "part.h5"), "-o", str(out)])
    assert rc != 0
    err = one_line(capsys.readouterr().err)
    assert "part.h5" in err and "topology differs" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bfm.h5", "part.h5"]


# -- bad input ----------------------------------------------------------------

def make_bad(tmp_path: Path, how: str) -> Path:
    path = tmp_path / f"bad-{how}.h5"
    if how == "pickle-npz":
        path = path.with_suffix(".npz")
        np.savez(path, MU=np.zeros(3), PC=np.array([{"x": 1}], dtype=object))
        return path
    if how == "pickle-file":
        path.write_bytes(pickle.dumps([1, 2]))
        return path
    if how == "not-hdf5":
        path.write_text("plain text\n")
        return path
    write_bfm2017_like(path)
    if how == "truncated":
        path.write_bytes(path.read_bytes()[:2000])
        return path
    with h5py.File(path, "r+") as h5:
        if how == "missing-dataset":
            del h5["color/model/pcaVariance"]
        elif how == "wrong-shape":
            del h5["shape/representer/points"]
            h5["shape/representer/points"] = np.zeros((2, NX * NY), np.float32)
        elif how == "nan":
            h5["expression/model/pcaBasis"][0, 0] = np.nan
    return path


@pytest.mark.parametrize("how", ["truncated", "not-hdf5", "missing-dataset", "wrong-shape",
                                 "nan", "pickle-npz", "pickle-file"])
def test_bad_input_cli(tmp_path: Path, capsys: pytest.CaptureFixture, how: str) -> None:
    path = make_bad(tmp_path, how)
    assert main(["model", "info", str(path)]) != 0
    captured = capsys.readouterr()
    err = one_line(captured.err)
    assert str(path) in err and err.startswith("mcmcfit model: error:")
    if how.startswith("pickle"):
        assert "needs pickle; refusing to unpickle" in err
    assert captured.out == ""


def test_bad_shape_in_combine_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    write_bfm2017_like(tmp_path / "bfm.h5")
    bad = make_bad(tmp_path, "nan")
    rc = main(["model", "combine", "--shape", str(bad), "--albedo", str(tmp_path / "bfm.h5"),
               "-o", str(tmp_path / "joint.h5")])
    assert rc != 0 and "NaN" in one_line(capsys.readouterr().err)
    assert not (tmp_path / "joint.h5").exists()


def test_default_model_from_cache(
    tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    from albedo_model.default_model import default_model_path
    from albedo_model.io.momo_h5 import write_model_h5

    from albedo_model.model import MorphableModel

    import pipeline.synthetic.default_model

    monkeypatch.setenv("MCMCFIT_CACHE", str(tmp_path))
    monkeypatch.setattr(pipeline.synthetic.default_model, "default_model_fingerprint", lambda: "test")
    v, t = grid()
    rng = np.random.default_rng(0)
    part = lambda: PCAPart(rng.random(v.size, np.float32), np.eye(v.size, 2, dtype=np.float32),  # noqa: E731
                           np.ones(2, np.float32))
    write_model_h5(MorphableModel(v, t, part(), part(), specular=part()),
                   default_model_path('test', must_exist=False))
    assert main(["model", "info", "default", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["path"] == str(default_model_path())

