"""Synthetic cases: determinism, landmarks on the rendered face, true albedo, hard-case options."""

from __future__ import annotations

import numpy as np
import pytest
from face_factory import small_face_model

from albedo_model.camera import project
from albedo_model.errors import InputError
from albedo_model.io.model_files import load_model
from albedo_model.render.renderer import Renderer
from mcmcfit.jobs.synthetic_case import DARK_SKIN_ALBEDO, synthetic_case


@pytest.fixture(scope="module")
def small_model():
    return small_face_model()


@pytest.fixture(scope="module")
def default_model(default_model_file):
    return load_model(default_model_file)


def _true_mask(model, case):
    return Renderer(model, specular=False, threads=1).render(case.truth).mask


def test_same_seed_same_case_and_seeds_differ(small_model):
    a = synthetic_case(small_model, seed=3, size=64)
    b = synthetic_case(small_model, seed=3, size=64)
    c = synthetic_case(small_model, seed=4, size=64)
    assert np.array_equal(a.image, b.image)
    assert a.landmarks.keys() == b.landmarks.keys()
    assert all(np.array_equal(a.landmarks[k], b.landmarks[k]) for k in a.landmarks)
    assert np.array_equal(a.diffuse, b.diffuse) and a.truth.pose == b.truth.pose
    assert not np.array_equal(a.image, c.image)
    assert a.truth.pose != c.truth.pose


def test_image_is_an_8bit_gamma_encoded_picture(small_model):
    case = synthetic_case(small_model, seed=1, size=64)
    assert case.image.shape == (64, 64, 3) and case.image.dtype == np.float64
    assert case.image.min() >= 0.0 and case.image.max() <= 1.0
    assert np.allclose(case.image * 255.0, np.round(case.image * 255.0))


def test_landmarks_project_onto_the_rendered_face(small_model):
    case = synthetic_case(small_model, seed=2, size=96, yaw_deg=20.0)
    assert len(case.landmarks) >= 6
    mask = _true_mask(small_model, case)
    m = case.truth.momo
    verts = small_model.shape_instance(m.shape, m.expression)
    lv = small_model.landmark_vertices
    for name, px in case.landmarks.items():
        # independent projection of the true 3-D landmark
        p, _ = project(verts[[lv[name]]], case.truth.pose, case.truth.view, case.truth.camera,
                       case.truth.image_size)
        assert np.allclose(p[0], px, atol=1e-6)
        x, y = int(np.floor(px[0])), int(np.floor(px[1]))
        assert mask[max(0, y - 1):y + 2, max(0, x - 1):x + 2].any(), name


def test_truth_albedo_and_visibility(small_model):
    case = synthetic_case(small_model, seed=5, size=64)
    assert np.allclose(case.diffuse, small_model.diffuse_instance(case.truth.momo.albedo))
    assert case.specular is not None and case.specular.shape == case.diffuse.shape
    assert 0 < case.visible.sum() < small_model.n_vertices
    no_spec = synthetic_case(small_model, seed=5, size=64, specular=False)
    assert no_spec.specular is None


def test_face_width_option_sets_the_face_size(small_model):
    case = synthetic_case(small_model, seed=0, size=128, face_width_px=24, yaw_deg=0.0)
    cols = np.flatnonzero(_true_mask(small_model, case).any(axis=0))
    assert 18 <= cols.max() - cols.min() + 1 <= 30


def test_bad_options_are_input_errors(small_model):
    with pytest.raises(InputError):
        synthetic_case(small_model, skin="green")
    with pytest.raises(InputError):
        synthetic_case(small_model, background="stars")


def test_default_model_dark_skin_and_lfw_landmarks(default_model):
    case = synthetic_case(default_model, seed=0, skin="dark")
    assert len(case.landmarks) >= 12
    dark = case.diffuse[case.visible].mean(0)
    assert np.all(np.abs(dark - np.asarray(DARK_SKIN_ALBEDO)) < 0.02)
    normal = synthetic_case(default_model, seed=0)
    assert np.all(normal.diffuse[normal.visible].mean(0) > dark)


def test_default_model_cases_have_physical_albedo(default_model):
    # about one in six plain N(0, 1) draws of the default model is darker than
    # Fitzpatrick VI somewhere (negative blue); cases must be physical faces
    for seed in range(25):
        d = synthetic_case(default_model, seed=seed, size=32).diffuse
        out = (d.min(axis=1) < 0.005) | (d.max(axis=1) > 1.0)
        assert out.mean() <= 0.05, seed
