"""Result folder of a fit: files, posterior.npz against the chains, re-rendering, atomicity."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.errors import InputError
from albedo_model.io.image_io import read_image
from albedo_model.io.momo_h5 import write_model_h5
from albedo_model.io.rps import read_rps
from albedo_model.params import ColorTransform, SHLight
from albedo_model.render.renderer import Renderer
from mcmcfit.sampling.chain_file import read_chains_h5
from mcmcfit.cli import main
from mcmcfit.fitting.config import FitConfig
from mcmcfit.jobs.fit_job import LoadedModel, atomic_folder, fit_into_folder
from mcmcfit.outputs import OUTPUT_FILES
from mcmcfit.outputs.summary import landmark_errors
from mcmcfit.outputs.truth import Truth, albedo_error
from mcmcfit.outputs.vertex_maps import frontal_params, vertex_image
from mcmcfit.outputs.posterior import AlbedoPosterior, albedo_posterior, visible_vertices

CFG = FitConfig(steps=200, landmark_steps=200, chains=2, thin=5, sigma_lm=2.0)


@pytest.fixture(scope="module")
def small_model():
    return small_face_model()


@pytest.fixture(scope="module")
def target(small_model):
    truth = scene(64, 64, yaw=0.25, pitch=-0.1)
    image, clicks = synthetic_target(small_model, truth)
    return image, clicks, truth


@pytest.fixture(scope="module")
def result_folder(small_model, target, tmp_path_factory):
    image, clicks, _ = target
    out = tmp_path_factory.mktemp("outputs") / "fit"
    loaded = LoadedModel(small_model, "0" * 64, "small-test-model")
    summary = fit_into_folder(image, clicks, loaded, out, config=CFG, seed=5)
    return out, summary


def test_folder_holds_every_output(result_folder):
    out, summary = result_folder
    names = {p.name for p in out.iterdir()}
    expected = set(OUTPUT_FILES) | {f"{k}_specular_{v}.png" for k in ("albedo", "uncertainty")
                                    for v in ("fitted", "frontal")}
    assert expected <= names
    assert set(summary["files"]) == names
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]  # no leftovers
    on_disk = json.loads((out / "summary.json").read_text())
    assert on_disk == summary
    for key in ("seed", "model_sha256", "version", "steps", "timings", "acceptance", "ess",
                "rhat", "landmark_rmse_px", "landmarks"):
        assert key in summary
    assert summary["seed"] == 5 and summary["model_sha256"] == "0" * 64
    assert {"stage1_s", "stage2_s", "total_s"} <= set(summary["timings"])
    assert summary["steps"] == {"landmark": 200, "image": 200, "chains": 2, "thin": 5,
                                "stage1_sampler": "mh"}
    assert sum(a["proposed"] for a in summary["acceptance"].values()) == 2 * 200
    assert FitConfig.from_json((out / "config.json").read_text()) == CFG
    # files are readable by others as the umask allows (temporary files start private)
    mask = os.umask(0)
    os.umask(mask)
    assert (out / "posterior.npz").stat().st_mode & 0o777 == 0o666 & ~mask


def test_posterior_npz_matches_the_chains(result_folder, small_model):
    out, _ = result_folder
    post = np.load(out / "posterior.npz")
    n = small_model.n_vertices
    for part in ("diffuse", "specular"):
        for f in ("mean", "std", "lo", "hi"):
            assert post[f"{part}_{f}"].shape == (n, 3)
    assert post["visible"].shape == (n,) and post["visible"].dtype == bool
    # recompute from the samples stored in chain.h5 (an independent path through the file)
    chains, layout, _ = read_chains_h5(out / "chain.h5")
    cols = layout.slice("albedo")
    pooled = np.concatenate([c.stage2.samples[int(CFG.burn_fraction * c.stage2.samples.shape[0]):
                                              , cols] for c in chains])
    ref = albedo_posterior(small_model.diffuse, pooled)  # the model has no residual variance
    np.testing.assert_allclose(post["diffuse_mean"], ref.mean, atol=1e-6)
    np.testing.assert_allclose(post["diffuse_coef_hi"], ref.hi, atol=1e-6)
    assert np.all(post["diffuse_lo"] <= post["diffuse_hi"])
    # the predictive intervals add the out-of-span variance read off the photograph
    # (mcmcfit.outputs.residual_scale): per channel, the same for every vertex
    scale = post["diffuse_residual_scale"]
    assert bool(post["diffuse_predictive"]) and scale.shape == (3,) and np.all(scale >= 0)
    np.testing.assert_allclose(post["diffuse_std"] ** 2, ref.std ** 2 + scale[None, :],
                               rtol=1e-4, atol=1e-9)
    # visible: vertices hit when rendering best.rps
    best = read_rps(out / "best.rps")
    r = Renderer(small_model, threads=1)
    np.testing.assert_array_equal(post["visible"], visible_vertices(r, r.init_state(best)))


def test_posterior_nc_holds_the_chains_and_the_target(result_folder, small_model, target):
    """posterior.nc against chain.h5 (an independent path), and ArviZ reads it as is."""
    from mcmcfit.sampling.diagnostics import arviz

    out, summary = result_folder
    az = arviz()
    idata = az.from_netcdf(out / "posterior.nc")
    chains, layout, _ = read_chains_h5(out / "chain.h5")
    n = min(c.stage2.samples.shape[0] for c in chains)
    start = int(CFG.burn_fraction * n)
    assert idata.posterior.sizes["chain"] == 2 and idata.posterior.sizes["draw"] == n - start
    for i, c in enumerate(chains):
        np.testing.assert_array_equal(idata.posterior["albedo"][i],
                                      c.stage2.samples[start:n, layout.slice("albedo")])
        np.testing.assert_array_equal(idata.sample_stats["lp"][i],
                                      c.stage2.log_posterior[c.stage2.sample_step[start:n]])
    np.testing.assert_allclose(idata.observed_data["image"], np.clip(target[0], 0, 1))
    assert set(idata.observed_data["landmark"].values) == set(target[1])
    assert idata.posterior.attrs["seed"] == 5
    assert idata.posterior.attrs["model_sha256"] == "0" * 64
    if "albedo_mean" in idata.posterior:  # the small model has eye landmarks only
        assert "eyes" in idata.posterior["region"].values
    with np.errstate(all="ignore"):
        table = az.summary(idata, var_names=["pose", "albedo"])
    assert "albedo[0]" in table.index
    assert "posterior.nc" in summary["files"]


def test_best_rps_rerenders_like_fit_png(result_folder, small_model, tmp_path):
    out, _ = result_folder
    model_file = tmp_path / "small.h5"
    write_model_h5(small_model, model_file)
    png = tmp_path / "best.png"
    assert main(["render", str(model_file), str(out / "best.rps"), "-o", str(png)]) == 0
    import imageio.v3 as iio

    rgba = iio.imread(png) / 255.0
    fit = read_image(out / "fit.png")
    face = rgba[..., 3] > 0.5
    assert face.sum() > 200
    # fit.png is the same render over the target: equal up to 8-bit rounding
    assert np.max(np.abs(rgba[..., :3][face] - fit[face])) <= 1.5 / 255
    assert main(["render", str(model_file), str(out / "mean.rps"), "-o", str(png)]) == 0


def test_vertex_image_equals_albedo_render_under_ambient_white(small_model):
    p = scene(48, 40, yaw=0.4, pitch=0.2)
    p = p._replace(environment_map=SHLight.ambient_white(), color_transform=ColorTransform())
    r = Renderer(small_model, specular=False, threads=1)
    state = r.init_state(p)
    rendered = r.image(state)
    img, mask = vertex_image(state, small_model.diffuse_instance())
    assert img.shape == (40, 48, 3)
    np.testing.assert_array_equal(mask, rendered.mask)
    np.testing.assert_allclose(img[mask], rendered.image[mask], atol=2e-5)
    scalar, _ = vertex_image(state, small_model.diffuse_instance()[:, 1])
    np.testing.assert_allclose(scalar, img[..., 1], atol=1e-6)


def test_frontal_view_frames_the_landmarks(small_model):
    p = frontal_params(scene(64, 64, yaw=0.8, pitch=0.3), small_model, size=(100, 80))
    assert (p.pose.yaw, p.pose.pitch, p.pose.roll) == (0.0, 0.0, 0.0)
    r = Renderer(small_model, threads=1)
    state = r.init_state(p)
    names, px, vis = r.landmarks(state)
    front = [n for n in names if "ear" not in n and "back" not in n]
    pts = np.array([px[names.index(n)] for n in front])
    assert np.all((pts[:, 0] > 0) & (pts[:, 0] < 100) & (pts[:, 1] > 0) & (pts[:, 1] < 80))
    # the nose tip is in the middle column (a frontal, centred view of a symmetric head)
    assert abs(px[names.index("center.nose.tip")][0] - 50) < 3


def test_landmark_errors_and_truth_errors_by_hand():
    e = landmark_errors({"a": np.array([0.0, 0.0]), "b": np.array([1.0, 1.0])}, ["a", "b", "c"],
                        np.array([[3.0, 4.0], [1.0, 1.0], [9.0, 9.0]]))
    assert e["per_landmark_px"] == {"a": 5.0, "b": 0.0}
    assert e["rmse_px"] == pytest.approx(np.sqrt(12.5))
    mean = np.array([[0.1, 0.2, 0.3], [0.5, 0.5, 0.5]])
    lo, hi = mean - 0.05, mean + 0.05
    part = AlbedoPosterior(mean, np.zeros_like(mean), lo, hi, 0.9)

    class Post:
        diffuse, specular = part, None

    true = np.array([[0.1, 0.2, 0.4], [9.0, 9.0, 9.0]])
    err = albedo_error(Post, Truth(true, None, np.array([True, False])))
    assert err["diffuse"]["rmse"] == pytest.approx(np.sqrt(0.01 / 3))
    assert err["diffuse"]["coverage"] == pytest.approx(2 / 3)
    assert err["n_visible"] == 1 and "specular" not in err


def test_failed_write_leaves_nothing(tmp_path):
    out = tmp_path / "res"
    with pytest.raises(RuntimeError):
        with atomic_folder(out) as tmp:
            (tmp / "half.txt").write_text("x")
            raise RuntimeError("disk full")
    assert list(tmp_path.iterdir()) == []
    out.mkdir()
    (out / "old.txt").write_text("old")
    with pytest.raises(InputError, match="exists"):
        with atomic_folder(out):
            pass
    with atomic_folder(out, force=True) as tmp:
        (tmp / "new.txt").write_text("new")
    assert [p.name for p in tmp_path.iterdir()] == ["res"]
    assert [p.name for p in out.iterdir()] == ["new.txt"]


def test_fit_error_writes_nothing(small_model, target, tmp_path):
    image, clicks, _ = target
    out = tmp_path / "res"
    with pytest.raises(InputError):
        fit_into_folder(image[:, :, :2], clicks, LoadedModel(small_model), out, config=CFG)
    assert list(tmp_path.iterdir()) == []
