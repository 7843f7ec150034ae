"""The model colour space in a fit: FitConfig.model_colour, comparison space, decoded outputs."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from colour_factory import srgb_case
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.errors import InputError
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.fit import fit
from mcmcfit.fitting.problem import comparison_colour
from mcmcfit.jobs.fit_job import LoadedModel, fit_into_folder
from mcmcfit.outputs.albedo_summary import posterior_albedo
from mcmcfit.outputs.truth import Truth
from mcmcfit.targets.image import linearise, prepare_image_target

#: A short schedule: the two readings of the model differ by far more than its noise.
SHORT = {"steps": 200, "landmark_steps": 200, "chains": 2, "parallel": False, "sigma_lm": 2.0}


@pytest.fixture(scope="module")
def case():
    return srgb_case()


def _rmse(a, b, visible) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, float)[visible] - b[visible]) ** 2)))


def test_config_validates_and_round_trips_model_colour():
    assert FitConfig().model_colour is None
    for value in ("linear", "srgb"):
        cfg = FitConfig(model_colour=value)
        assert FitConfig.from_json(cfg.to_json()).model_colour == value
    for bad in ("sRGB", "gamma", 2):
        with pytest.raises(InputError, match="model_colour must be 'linear', 'srgb' or None"):
            FitConfig(model_colour=bad)
    # a config.json written before the setting existed still reads (None: from the model)
    old = json.loads(FitConfig().to_json())
    del old["model_colour"]
    assert FitConfig.from_dict(old).model_colour is None


def test_the_target_is_compared_in_the_models_colour_space(case):
    lin = prepare_image_target(case.image)
    assert lin.colour == "linear" and np.array_equal(lin.linear, linearise(case.image))
    enc = prepare_image_target(case.image, colour="srgb")
    assert enc.colour == "srgb" and np.array_equal(enc.linear, np.clip(case.image, 0, 1))
    assert np.array_equal(np.asarray(enc.arrays.rgb[1]), case.image[..., 1].astype(np.float32))
    with pytest.raises(InputError, match="'linear' or 'srgb'"):
        prepare_image_target(case.image, colour="gamma")
    # the fit's choice: the config's override, else the model's own colour space
    def problem(model, cfg):
        return SimpleNamespace(model=model, config=cfg)

    assert comparison_colour(problem(case.model, FitConfig())) == "srgb"
    assert comparison_colour(problem(case.model, FitConfig(model_colour="linear"))) == "linear"
    assert comparison_colour(problem(small_face_model(), FitConfig())) == "linear"


@pytest.mark.parametrize("seed", [0, 1])
def test_srgb_fit_reports_the_linear_albedo(case, seed):
    res = fit(case.image, case.clicks, case.model, config=FitConfig(**SHORT), seed=seed)
    post = posterior_albedo(res, case.model, case.visible)
    assert post.colour == "srgb"
    # the reference's reading: the decoded posterior mean is the face's linear albedo
    assert _rmse(post.diffuse.mean, case.true_linear, case.visible) < 0.03


def test_reading_the_srgb_texture_as_linear_albedo_is_far_off(case):
    cfg = FitConfig(**SHORT, model_colour="linear")
    res = fit(case.image, case.clicks, case.model, config=cfg, seed=0)
    post = posterior_albedo(res, case.model, case.visible)
    assert post.colour == "linear"
    err = np.asarray(post.diffuse.mean, float)[case.visible] - case.true_linear[case.visible]
    # the misread texture comes back as too bright "albedo" (encoded values ~ linear^(1/2.4))
    assert _rmse(post.diffuse.mean, case.true_linear, case.visible) > 0.1
    assert np.all(err.mean(0) > 0.1)


def test_linear_path_is_unchanged_by_naming_it():
    model = small_face_model(specular=False)
    image, clicks = synthetic_target(model, scene(48, 48, yaw=0.2))
    cfg = FitConfig(steps=40, landmark_steps=40, chains=1, parallel=False, warmup_steps=20)
    a = fit(image, clicks, model, config=cfg, seed=5)
    b = fit(image, clicks, model, config=cfg.replace(model_colour="linear"), seed=5)
    assert np.array_equal(a.chains[0].stage2.samples, b.chains[0].stage2.samples)
    assert a.best.log_lik_img == b.best.log_lik_img


@pytest.mark.filterwarnings("ignore:the chains have NOT converged")
def test_result_folder_of_an_srgb_model(case, tmp_path):
    truth = Truth(case.true_linear, None, case.visible)
    summary = fit_into_folder(case.image, case.clicks, LoadedModel(case.model), tmp_path / "out",
                              config=FitConfig(**SHORT), seed=0, truth=truth)
    on_disk = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert on_disk["model"] == summary["model"]
    assert on_disk["model"]["colour_space"] == "srgb"
    assert on_disk["model"]["colour_space_source"] == "model metadata"
    assert "decoded" in on_disk["model"]["colour_handling"]
    assert on_disk["config"]["model_colour"] is None
    # every reported albedo is linear: the truth error and posterior.npz are decoded
    assert on_disk["truth"]["diffuse"]["rmse"] < 0.03
    with np.load(tmp_path / "out" / "posterior.npz") as npz:
        assert _rmse(npz["diffuse_mean"], case.true_linear, case.visible) < 0.03
    assert "model colour" in (tmp_path / "out" / "report.html").read_text()
    import arviz

    attrs = arviz.from_netcdf(tmp_path / "out" / "posterior.nc").posterior.attrs
    assert json.loads(attrs["model_colour"])["colour_space"] == "srgb"
    assert "encoded" in attrs["albedo_mean_space"]
