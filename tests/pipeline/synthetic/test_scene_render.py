"""Scene photographs: only the effects a scene asks for are computed; cast shadows when asked."""

from __future__ import annotations

import time

import numpy as np
import pytest

from albedo_model.errors import InputError
from albedo_model.io.colour_space import model_colour_space
from albedo_model.io.model_files import load_model
from pipeline.synthetic.baked_model import bake_textures, build_baked_model
from pipeline.synthetic.scene_render import render_scene, truth_model
from pipeline.synthetic.scenes import SCENES, scene_spec

CLEAN = {"white_balance_sd": 0.0, "read_noise": 0.0, "shot_noise": 0.0, "jpeg_quality": None}


@pytest.fixture(scope="module")
def model(default_model_file):
    return load_model(default_model_file)


def _maps(model):
    return (model.diffuse.mean.reshape(-1, 3).astype(float),
            model.specular.mean.reshape(-1, 3).astype(float))


def test_truth_model_renders_the_given_maps(model):
    d, s = _maps(model)
    tm = truth_model(model, 0.5 * d, s)
    np.testing.assert_allclose(tm.diffuse_instance(np.zeros(1)).reshape(-1), 0.5 * d.reshape(-1), rtol=1e-6)
    assert tm.ranks["diffuse"] == 1 and tm.ranks["shape"] == model.ranks["shape"]


def test_only_the_asked_effects_are_computed(model):
    d, s = _maps(model)
    seconds = {}
    for name in SCENES:
        t0 = time.perf_counter()
        photo = render_scene(model, d, s, scene_spec(name), seed=3, size=64)
        seconds[name] = time.perf_counter() - t0
        assert ("shadow rays" in photo.computed) == (name == "directional"), name
        assert (photo.timings["shadow_rays"] > 0) == (name == "directional"), name
        assert ("JPEG" in photo.computed) == (photo.suffix == ".jpg")
        assert photo.image.shape == (64, 64, 3) and photo.visible.any() and photo.landmarks
    sh = render_scene(model, d, s, scene_spec("sh"), seed=3, size=64)
    assert sh.computed == ["specular"] and sh.suffix == ".png"
    np.testing.assert_array_equal(sh.colour_matrix, np.eye(3))
    print("seconds per scene (64 px):", {k: round(v, 3) for k, v in seconds.items()})


def test_cast_shadows_only_when_asked(model):
    d, s = _maps(model)
    spec = scene_spec("directional", **CLEAN)
    lit = render_scene(model, d, s, spec, seed=4, size=96)
    unshadowed = render_scene(model, d, s, scene_spec("directional", shadows=False, **CLEAN),
                              seed=4, size=96)
    assert "shadow rays" in lit.computed and "shadow rays" not in unshadowed.computed
    diff = unshadowed.image - lit.image        # same pose, light and background
    assert diff.min() > -2 / 255                # a shadow only darkens
    assert (diff.max(axis=2) > 0.02).sum() >= 5  # and there is one (the nose, the cheek)


def test_profile_and_dark_scenes(model):
    assert scene_spec("profile").yaw_deg == (45.0, 70.0)
    assert set(scene_spec("dark").fitzpatrick) == {5, 6}
    with pytest.raises(Exception, match="unknown scene"):
        scene_spec("moonlight")
    with pytest.raises(Exception, match="unknown scene field"):
        scene_spec("sh", glare=True)


def test_baked_model_is_marked_srgb_and_bakes_shading(model):
    from types import SimpleNamespace

    d, s = _maps(model)
    subjects = [SimpleNamespace(diffuse=d * f, specular=s) for f in (0.8, 1.0, 1.2)]
    baked = build_baked_model(model, subjects, 2)
    assert baked.specular is None and baked.ranks["diffuse"] == 2
    assert model_colour_space(baked).value == "srgb"
    assert model_colour_space(build_baked_model(model, subjects, 2, colour="linear")).value == "linear"
    normals = np.tile([0.0, 0.0, 1.0], (len(d), 1))
    flat = bake_textures(d, 0 * s, normals)
    side = bake_textures(d, 0 * s, np.tile([1.0, 0.0, 0.0], (len(d), 1)))
    assert np.all(flat >= side)  # the key light comes from the front-left: shading baked in


def test_one_person_in_several_scenes(model):
    """A given shape replaces the seed's draw and nothing else: the scene is the seed's."""
    d, s = _maps(model)
    spec = scene_spec("sh", **CLEAN)
    drawn = render_scene(model, d, s, spec, seed=5, size=64)
    identity = np.zeros(model.ranks["shape"])
    identity[:3] = (1.0, -0.5, 0.25)
    a = render_scene(model, d, s, spec, seed=5, size=64, shape=identity)
    b = render_scene(model, d, s, spec, seed=6, size=64, shape=identity)
    np.testing.assert_array_equal(a.truth.momo.shape, identity)
    np.testing.assert_array_equal(b.truth.momo.shape, identity)
    assert a.truth.pose == drawn.truth.pose  # the rest of seed 5's scene
    assert a.truth.pose != b.truth.pose
    with pytest.raises(InputError, match="model's 40 coefficients"):
        render_scene(model, d, s, spec, seed=5, size=64, shape=np.zeros(3))
