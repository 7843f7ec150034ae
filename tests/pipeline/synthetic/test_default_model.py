"""The built-in default model: loader path, landmarks, symmetry closure, determinism."""

from __future__ import annotations

import json

import numpy as np
import pytest

from albedo_model.io.model_files import load_model, model_file_kind
from mcmcfit.cli import main
from pipeline.synthetic.default_model import build_default_model

LFW_TLMS_NAMES = [
    "left.eyebrow.bend.lower", "right.eyebrow.bend.lower", "left.eyebrow.inner_lower",
    "right.eyebrow.inner_lower", "left.eye.corner_outer", "right.eye.corner_outer",
    "left.eye.corner_inner", "right.eye.corner_inner", "left.nose.wing.tip", "right.nose.wing.tip",
    "center.nose.tip", "left.lips.corner", "right.lips.corner", "center.lips.upper.outer",
    "center.lips.lower.outer", "center.chin.tip",
]


@pytest.fixture(scope="module")
def model(default_model_file):
    return load_model(default_model_file)


def test_model_info_default_lists_lfw_landmarks(default_model_file, capsys):
    assert main(["model", "info", "default", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["path"] == str(default_model_file)
    assert set(LFW_TLMS_NAMES) <= set(info["landmarks"])
    assert info["landmarks_on_vertices"] == len(info["landmarks"])
    assert info["format"].startswith("AlbedoMM HDF5")
    assert 10_000 <= info["vertices"] <= 30_000
    assert info["parts"]["diffuse"] == info["parts"]["specular"]


def test_loads_through_the_albedomm_reader(default_model_file, model):
    assert model_file_kind(default_model_file) == "albedomm"
    assert model.shared_albedo and model.specular is not None and model.expression is not None
    assert model.metadata["synthetic"] == "true"
    assert model.metadata["colour_space"] == "linear sRGB"
    assert model.symmetry is not None
    np.testing.assert_array_equal(model.symmetry[model.symmetry], np.arange(model.n_vertices))


def _mirror_shape(flat, sym):
    v = flat.reshape(-1, 3)[sym].copy()
    v[:, 0] *= -1
    return v.ravel()


def _residual(part, x):
    c = part.project(x, regularization=0.0)
    return np.linalg.norm(part.instance(c) - x) / np.linalg.norm(x - part.mean)


def test_mirrored_samples_stay_in_the_model(model):
    rng = np.random.default_rng(3)
    sym = model.symmetry
    shape = model.shape.sample(rng)
    assert _residual(model.shape, _mirror_shape(shape, sym)) < 0.02
    diffuse = model.diffuse.sample(rng)
    mirrored = diffuse.reshape(-1, 3)[sym].ravel()
    assert _residual(model.diffuse, mirrored) < 0.02


def test_mean_diffuse_albedo_is_skin_coloured(model):
    skin = model.diffuse.mean.reshape(-1, 3)
    med = np.median(skin, axis=0)
    assert np.all(med > (0.06, 0.03, 0.02)) and np.all(med < (0.5, 0.32, 0.27))
    assert med[0] > med[1] > med[2]  # red > green > blue


def test_rebuild_from_the_same_seed_is_identical():
    kw = dict(seed=7, n_subjects=6, shape_rank=5, albedo_rank=5)
    a, b = build_default_model(**kw), build_default_model(**kw)
    for name in ("shape", "expression", "diffuse", "specular"):
        pa, pb = getattr(a, name), getattr(b, name)
        np.testing.assert_array_equal(pa.mean, pb.mean)
        np.testing.assert_array_equal(pa.basis, pb.basis)
        np.testing.assert_array_equal(pa.variance, pb.variance)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    c = build_default_model(**{**kw, "seed": 8})
    assert not np.array_equal(a.diffuse.basis, c.diffuse.basis)


def test_model_sample_grid(default_model_file, tmp_path):
    import imageio.v3 as iio

    out = tmp_path / "grid.png"
    assert main(["model", "sample", "default", "--n", "6", "--size", "64", "--columns", "3",
                 "-o", str(out)]) == 0
    grid = iio.imread(out)
    assert grid.shape == (128, 192, 3)
    # every tile shows a face (non-white pixels) of plausible skin colour
    tiles = grid.reshape(2, 64, 3, 64, 3).transpose(0, 2, 1, 3, 4).reshape(6, 64, 64, 3)
    for t in tiles:
        face = t[(t < 250).any(-1)]
        assert len(face) > 0.2 * 64 * 64
        assert face[:, 0].mean() > face[:, 2].mean()
