"""The face region of the template head and the built-in ``default-face`` crop of the default model."""

from __future__ import annotations

import json

import numpy as np
import pytest

from albedo_model.io.model_files import default_face_model_path, load_model, model_file_kind
from albedo_model.model_crop import crop_model_with_maps
from mcmcfit.cli import main
from mcmcfit.jobs.model_spec import load_model_spec, resolve_model
from mcmcfit.jobs.synthetic_case import LFW_TLMS_NAMES
from pipeline.synthetic.default_face_model import build_default_face_model
from pipeline.synthetic.face_region import face_region
from pipeline.synthetic.head.template_head import build_template_head


@pytest.fixture(scope="module")
def head():
    return build_template_head()


@pytest.fixture(scope="module")
def face(head):
    return face_region(head)


def _at(head, name):
    return head.vertices[head.landmarks[name]]


def test_the_face_is_a_symmetric_clean_patch(head, face):
    assert 0.3 * head.n_vertices < face.sum() < 0.6 * head.n_vertices
    np.testing.assert_array_equal(face, face[head.symmetry])
    inside = head.triangles[np.all(face[head.triangles], axis=1)]
    np.testing.assert_array_equal(np.unique(inside), np.flatnonzero(face))  # no loose vertex
    # one connected surface: grow from the nose tip along the inside triangles
    reached = np.zeros(head.n_vertices, bool)
    reached[head.landmarks["center.nose.tip"]] = True
    for _ in range(400):
        grow = np.any(reached[inside], axis=1)
        new = reached.copy()
        new[inside[grow].ravel()] = True
        if np.array_equal(new, reached):
            break
        reached = new
    np.testing.assert_array_equal(reached, face)


def test_no_ears_no_scalp_no_neck(head, face):
    v = head.vertices[face]
    assert not np.any(face & head.regions["ears"])
    assert v[:, 2].min() > _at(head, "left.ear.tragus.tip")[2]   # in front of the ears
    assert v[:, 1].max() < _at(head, "center.front.trichion")[1] + 3.0  # the hairline
    chin = _at(head, "center.chin.tip")
    assert v[:, 1].min() > chin[1] - 20.0  # the chin's underside, not the neck
    # the neck below the chin (the throat and the front of the neck) is out
    neck = (np.abs(head.vertices[:, 0]) < 20) & (head.vertices[:, 1] < chin[1] - 25)
    assert neck.any() and not np.any(face & neck)
    # the scalp above the trichion is out; the ear landmarks are out
    assert not any(face[i] for name, i in head.landmarks.items() if ".ear." in name)


def test_the_face_keeps_eyes_lips_chin_and_every_fit_landmark(head, face):
    for region in ("eyeballs", "lips", "nose", "brows", "cheeks"):
        assert np.all(face[head.regions[region]]), region
    # the forehead up to the hairline (the template's forehead region reaches above it,
    # and at its lateral ends beyond the temples' hairline)
    lower_forehead = head.regions["forehead"] & (np.abs(head.vertices[:, 0]) < 40.0) & (
        head.vertices[:, 1] < _at(head, "center.front.trichion")[1] - 15.0)
    assert lower_forehead.sum() > 100 and np.all(face[lower_forehead])
    for name in LFW_TLMS_NAMES:
        assert face[head.landmarks[name]], name
    assert face[head.landmarks["center.front.trichion"]]
    # from ear to ear: the face reaches the sides of the head in front of the ears
    width = np.ptp(head.vertices[face, 0])
    assert width > 0.85 * np.ptp(head.vertices[:, 0][head.vertices[:, 2] > 0])


# -- the default-face model ------------------------------------------------------------

@pytest.fixture(scope="module")
def full(default_model_file):
    return load_model(default_model_file)


@pytest.fixture(scope="module")
def face_file(default_model_file):
    return resolve_model("default-face", progress=False)


def test_model_info_default_face(default_model_file, face_file, full, capsys):
    assert main(["model", "info", "default-face", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["path"] == str(face_file) == str(default_face_model_path())
    assert face_file.parent == default_model_file.parent  # cached beside the default model
    assert model_file_kind(face_file) == "albedomm"
    assert info["vertices"] < 0.6 * full.n_vertices
    assert info["parts"] == full.ranks and info["shared_albedo"]
    assert set(LFW_TLMS_NAMES) <= set(info["landmarks"])
    assert info["landmarks_on_vertices"] == len(info["landmarks"])
    record = json.loads(info["metadata"]["crop"])
    assert default_model_file.name in record["source"]
    assert record["vertices"] == [info["vertices"], full.n_vertices]
    assert info["metadata"]["synthetic"] == "true"


def test_default_face_is_the_marginal_of_default(full, head, face, face_file):
    crop = crop_model_with_maps(full, face)
    model = load_model_spec("default-face", progress=False)
    np.testing.assert_array_equal(model.vertices, full.vertices[crop.vertex_index])
    for name in ("shape", "expression", "diffuse", "specular"):
        np.testing.assert_array_equal(getattr(model, name).basis, getattr(crop.model, name).basis)
    rng = np.random.default_rng(5)
    maps = crop.coefficient_maps
    cs, ce, ca = (rng.standard_normal(full.ranks[k]) for k in ("shape", "expression", "diffuse"))
    want = full.shape_instance(cs, ce)[crop.vertex_index]
    got = model.shape_instance(maps["shape"] @ cs, maps["expression"] @ ce)
    assert np.abs(got - want).max() < 1e-4
    for a, b in ((model.diffuse_instance(maps["albedo"] @ ca), full.diffuse_instance(ca)),
                 (model.specular_instance(maps["albedo"] @ ca), full.specular_instance(ca))):
        assert np.abs(a - b[crop.vertex_index]).max() < 1e-5
    np.testing.assert_array_equal(crop.vertex_index[model.symmetry],
                                  full.symmetry[crop.vertex_index])
    assert model.triangles.max() < model.n_vertices


def test_the_crop_is_deterministic_and_cached(full, face_file):
    a, b = build_default_face_model(full), build_default_face_model(full)
    for name in ("shape", "expression", "diffuse", "specular"):
        for field in ("mean", "basis", "variance"):
            np.testing.assert_array_equal(getattr(getattr(a, name), field),
                                          getattr(getattr(b, name), field))
    mtime = face_file.stat().st_mtime_ns
    assert resolve_model("default-face", progress=False) == face_file
    assert face_file.stat().st_mtime_ns == mtime
