"""Model file resolution, content dispatch and combining (albedo_model.io.model_files)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
from momo_factory import synthetic_model

from albedo_model.errors import FormatError, InputError
from albedo_model.io.model_files import (
    combine_shape_albedo,
    file_sha256,
    load_model,
    model_file_kind,
    resolve_model_path,
)
from albedo_model.io.momo_h5 import AlbedoPart, write_albedo_part, write_model_h5


def test_resolve_default_before_it_is_built(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MCMCFIT_CACHE", str(tmp_path))
    with pytest.raises(InputError, match="has not been built yet"):
        resolve_model_path("default")


def test_resolve_default_from_the_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from albedo_model.default_model import default_model_path

    monkeypatch.setenv("MCMCFIT_CACHE", str(tmp_path))
    write_model_h5(synthetic_model(0), default_model_path('test', must_exist=False))
    assert resolve_model_path("default") == default_model_path()
    assert load_model("default").specular is not None


def test_resolve_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="none.h5: model file not found"):
        resolve_model_path(str(tmp_path / "none.h5"))


def test_kind_and_load_dispatch(tmp_path: Path) -> None:
    model = synthetic_model(1)
    momo = synthetic_model(1, specular=False)
    write_model_h5(model, tmp_path / "joint.h5")
    write_model_h5(momo, tmp_path / "momo.h5")
    part = AlbedoPart(model.vertices, model.triangles, model.diffuse, model.specular, {}, {})
    write_albedo_part(part, tmp_path / "part.h5")
    np.savez(tmp_path / "flame.npz", MU=np.zeros(6), PC=np.zeros((6, 1)))
    # names say nothing: dispatch is on content
    (tmp_path / "joint.h5").rename(tmp_path / "joint.bin")
    assert model_file_kind(tmp_path / "joint.bin") == "albedomm"
    assert model_file_kind(tmp_path / "momo.h5") == "momo"
    assert model_file_kind(tmp_path / "part.h5") == "albedo-part"
    assert model_file_kind(tmp_path / "flame.npz") == "flame-npz"
    assert load_model(tmp_path / "joint.bin").specular is not None
    assert load_model(str(tmp_path / "momo.h5")).specular is None
    with pytest.raises(FormatError, match="part.h5: an AlbedoMM albedo part"):
        load_model(tmp_path / "part.h5")
    with pytest.raises(FormatError, match="flame.npz: a texture-space FLAME"):
        load_model(tmp_path / "flame.npz")
    (tmp_path / "text.h5").write_text("nope")
    with pytest.raises(FormatError, match="text.h5: neither an HDF5 model nor an npz archive"):
        load_model(tmp_path / "text.h5")


def test_sha256(tmp_path: Path) -> None:
    data = np.random.default_rng(0).bytes(3 << 20)
    (tmp_path / "f").write_bytes(data)
    assert file_sha256(tmp_path / "f") == hashlib.sha256(data).hexdigest()


def test_combine_topology_checks() -> None:
    shape = synthetic_model(2, specular=False)
    albedo = synthetic_model(3)
    part = AlbedoPart(albedo.vertices, albedo.triangles, albedo.diffuse, albedo.specular, {}, {})
    joint = combine_shape_albedo(shape, part)
    assert joint.shape is shape.shape and joint.diffuse is albedo.diffuse
    assert joint.specular is albedo.specular and joint.shared_albedo
    flipped = albedo.triangles.copy()
    flipped[0] = flipped[0, ::-1]
    with pytest.raises(InputError, match="triangle lists are not identical"):
        combine_shape_albedo(shape, part._replace(triangles=flipped))
    with pytest.raises(InputError, match="topology differs"):
        combine_shape_albedo(shape, part._replace(vertices=albedo.vertices[:-1]))
