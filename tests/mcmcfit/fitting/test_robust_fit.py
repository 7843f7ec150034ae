"""A fit with ``foreground="robust"`` on a face half covered by an occluder.

The small synthetic face (known albedo) is rendered, and a block of dark
hair-like texture is painted over its upper part. Checked as a user reads the
result folder: the occlusion map finds the block (the painted pixels against
the rest of the face), ``summary.json`` says how much, and the posterior-mean
albedo of the vertices the occluder leaves free is closer to the truth than
the Gaussian foreground's, which bends shape, light and albedo to explain the
hair. Two seeds; the margins are wide: measured (2026-12-05) 35-39 % of the
face occluded (the block is 40 % of the face's rows), outlier probability 0.34,
diffuse RMSE 0.0013 / 0.0009 against the Gaussian foreground's 0.028 / 0.020.
How badly the Gaussian foreground fails depends on where its short chains go,
which differs between processors: on another machine (2026-12-07, AMD EPYC)
seed 1 measured 0.0031 against the Gaussian foreground's 0.0056. So the test
asserts the robust fit's own error (below 0.005, several times what it
measured) and that it beats the Gaussian foreground, not by how much.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.camera import project
from albedo_model.params import MoMoCoefficients
from albedo_model.render.renderer import Renderer
from mcmcfit.fitting.config import FitConfig
from mcmcfit.jobs.fit_job import LoadedModel, fit_into_folder
from mcmcfit.outputs.posterior import visible_vertices
from mcmcfit.outputs.truth import Truth

SIZE = 64
CFG = FitConfig(steps=100, landmark_steps=200, chains=2, thin=5, sigma_lm=2.0, parallel=False)


@pytest.fixture(scope="module")
def case():
    model = small_face_model()
    rng = np.random.default_rng(11)
    truth = scene(SIZE, SIZE, yaw=0.15, pitch=-0.05, coefficients=MoMoCoefficients(
        np.zeros(0), rng.normal(0, 0.8, model.diffuse.rank), np.zeros(0)))
    image, clicks = synthetic_target(model, truth)
    renderer = Renderer(model, specular=False, threads=1)
    state = renderer.init_state(truth)
    face = np.asarray(renderer.image(state).mask, bool)
    rows = np.flatnonzero(face.any(axis=1))
    block = np.zeros_like(face)
    block[rows[0]:rows[0] + (rows[-1] - rows[0]) * 2 // 5] = True
    hair = np.clip(0.12 + 0.04 * rng.standard_normal((SIZE, SIZE, 3)), 0, 1)
    occluded = np.where(block[..., None], hair, image)
    # the vertices the block leaves free: visible, projecting outside it
    pixels, _ = project(model.shape_instance(truth.momo.shape).reshape(-1, 3), truth.pose,
                        truth.view, truth.camera, truth.image_size)
    px = np.clip(np.round(pixels).astype(int), 0, SIZE - 1)
    free = visible_vertices(renderer, state) & ~block[px[:, 1], px[:, 0]]
    diffuse = model.diffuse_instance(np.asarray(truth.momo.albedo)).reshape(-1, 3)
    return model, occluded, clicks, face & block, face & ~block, Truth(diffuse, None, free)


def _fit(case, foreground, seed, out):
    model, image, clicks, _, _, truth = case
    loaded = LoadedModel(model, "0" * 64, "small-test-model")
    return fit_into_folder(image, clicks, loaded, out, config=CFG.replace(foreground=foreground),
                           seed=seed, truth=truth)


@pytest.mark.parametrize("seed", [1, 2])
def test_robust_fit_finds_the_occluder_and_fits_the_rest_better(case, seed, tmp_path):
    _, _, _, blocked, free_face, _ = case
    robust = _fit(case, "robust", seed, tmp_path / "robust")
    gaussian = _fit(case, "gaussian", seed, tmp_path / "gaussian")
    assert (tmp_path / "robust" / "occlusion.png").is_file()
    assert not (tmp_path / "gaussian" / "occlusion.png").exists()
    occ = robust["occlusion"]
    assert 0.1 < occ["occluded_fraction"] < 0.6
    assert robust["noise_model"]["outlier_probability"] > 0.05
    assert "robust foreground" in robust["noise_model"]["rule"]
    on_disk = json.loads((tmp_path / "robust" / "summary.json").read_text())
    assert on_disk["occlusion"] == occ
    err_r = robust["truth"]["diffuse"]["rmse"]
    err_g = gaussian["truth"]["diffuse"]["rmse"]
    assert err_r < 0.005, (err_r, err_g)
    assert err_r < err_g, (err_r, err_g)
