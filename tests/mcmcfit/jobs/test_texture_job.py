"""``mcmcfit texture``: a fit's maps as textures and a mesh, read back as a user would."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from momo_factory import synthetic_model

from albedo_model.io.image_io import read_image_pixels
from albedo_model.io.model_files import file_sha256
from albedo_model.io.momo_h5 import write_model_h5
from albedo_model.io.rps import write_rps
from albedo_model.params import default_square
from albedo_model.texture.bake import sample_texture
from mcmcfit.cli import main

pytest.importorskip("xatlas")

MAPS = ("mean", "std", "coef_std")


@pytest.fixture()
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MCMCFIT_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


def _fit_folder(root, model_path, n, *, seed=0):
    """The three files ``mcmcfit texture`` reads from a result folder."""
    rng = np.random.default_rng(seed)
    fit = root / "fit"
    fit.mkdir()
    arrays = {"visible": rng.uniform(size=n) > 0.3}
    for part in ("diffuse", "specular"):
        for m in MAPS:
            arrays[f"{part}_{m}"] = rng.uniform(0.05, 0.9, (n, 3)).astype(np.float32)
    np.savez(fit / "posterior.npz", **arrays)
    (fit / "summary.json").write_text(json.dumps(
        {"model_uri": str(model_path), "model_sha256": file_sha256(model_path)}))
    write_rps(fit / "mean.rps", default_square())
    return fit, arrays


@pytest.fixture()
def user_fit(tmp_path, cache):
    model = synthetic_model()
    path = tmp_path / "model.h5"
    write_model_h5(model, path)  # a user's model: no texture coordinates
    fit, arrays = _fit_folder(tmp_path, path, model.n_vertices)
    return fit, arrays, model


def test_textures_and_meshes_read_back_as_the_fit_maps(user_fit, cache, capsys):
    fit, arrays, model = user_fit
    assert main(["texture", str(fit), "--size", "64"]) == 0
    assert "UV atlas: computed with xatlas" in capsys.readouterr().out
    out = fit / "texture"
    record = json.loads((out / "texture.json").read_text())
    assert record["collisions"] == 0 and record["round_trip_max_abs_error"] < 1e-6
    assert list(cache.glob("uv-atlas/*.npz"))

    # the OBJ and the glTF load in trimesh with their textures; their UVs sample the
    # 16-bit linear texture back to the fit's per-vertex values
    obj = trimesh.load(out / "mesh.obj", process=False, maintain_order=True)
    glb = trimesh.load(out / "mesh.glb", force="mesh", process=False)
    for mesh in (obj, glb):
        assert len(mesh.faces) == model.n_triangles
        assert isinstance(mesh.visual, trimesh.visual.TextureVisuals)
    assert obj.visual.material.image.size == (64, 64)
    assert glb.visual.material.baseColorTexture.size == (64, 64)
    assert "map_Ks specular_mean_srgb8.png" in (out / "mesh.mtl").read_text()
    # which model vertex each OBJ vertex is: the mean-shape positions identify them
    verts = model.shape_instance()
    owner = np.argmin(((obj.vertices[:, None] - verts[None]) ** 2).sum(-1), axis=1)
    assert np.allclose(obj.vertices, verts[owner], atol=1e-4)
    for part in ("diffuse", "specular"):
        for m in MAPS:
            img = read_image_pixels(out / f"{part}_{m}_linear16.png")
            assert img.dtype == np.uint16 and img.shape == (64, 64, 3)
            back = sample_texture(img / 65535.0, obj.visual.uv)
            np.testing.assert_allclose(back, arrays[f"{part}_{m}"][owner], atol=1 / 65535)
            srgb = read_image_pixels(out / f"{part}_{m}_srgb8.png")
            assert srgb.dtype == np.uint8
    seen = read_image_pixels(out / "visible.png")
    assert set(np.unique(seen)) <= {0, 255}

    # second time: the cached atlas, and the folder is kept unless --force
    assert main(["texture", str(fit), "--size", "64"]) == 2
    assert (out / "texture.json").is_file()
    assert main(["texture", str(fit), "--size", "32", "--force"]) == 0
    again = json.loads((out / "texture.json").read_text())
    assert again["size"] == 32 and again["uv_atlas"].startswith("cached")


def test_bad_input_is_one_line_and_writes_nothing(user_fit, tmp_path, capsys):
    fit, _, _ = user_fit
    assert main(["texture", str(tmp_path / "nowhere")]) == 2
    assert "not a fit's result folder" in capsys.readouterr().err
    assert main(["texture", str(fit), "--size", "8"]) == 2
    assert ">= 16" in capsys.readouterr().err
    other = tmp_path / "other.h5"
    write_model_h5(synthetic_model().truncate(shape=2), other)  # same mesh: accepted, warned
    bigger = tmp_path / "bigger.h5"
    import dataclasses

    from momo_factory import grid_mesh, random_part

    v, t = grid_mesh(5, 3)
    rng = np.random.default_rng(0)
    m = dataclasses.replace(synthetic_model(), vertices=v, triangles=t, symmetry=None,
                            landmarks={}, shape=random_part(rng, v.size, 2),
                            expression=None, diffuse=random_part(rng, v.size, 2),
                            specular=random_part(rng, v.size, 2))
    write_model_h5(m, bigger)
    assert main(["texture", str(fit), "--model", str(bigger)]) == 2
    assert "15 vertices, the fit's maps 12" in capsys.readouterr().err
    assert not (fit / "texture").exists()
    assert main(["texture", str(fit), "--model", str(other), "--size", "16"]) == 0
    assert "not the file the fit used" in capsys.readouterr().err
