"""``mcmcfit fit IMG1 IMG2 --landmarks F1 F2``: a joint fit end to end, and its bad inputs.

Two renders of one small synthetic face (other yaw, expression and light),
fitted jointly from the command line with a short schedule. Checked: the
result folder (per-image fits, the shared albedo's posterior, which photograph
saw which vertex), that the identity is one in every recorded draw, each
image's pose against its truth, and that bad inputs are one line, exit code 2
and nothing written.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.errors import InputError
from albedo_model.io.image_io import write_png
from albedo_model.io.momo_h5 import write_model_h5
from albedo_model.io.rps import read_rps
from albedo_model.io.tlms import Landmark, write_tlms
from albedo_model.params import MoMoCoefficients, SHLight
from mcmcfit.cli import main
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.joint_fit import fit_joint

YAWS = (0.3, -0.3)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("joint")
    model = small_face_model()
    write_model_h5(model, root / "small.h5")
    rng = np.random.default_rng(1)
    identity = MoMoCoefficients(rng.normal(size=4), rng.normal(size=3), np.zeros(2))
    truths, images, landmarks = [], [], []
    for k, yaw in enumerate(YAWS):
        truth = scene(64, 64, yaw=yaw, coefficients=identity._replace(
            expression=rng.normal(0, 0.5, 2)))._replace(
            environment_map=SHLight.frontal(0.7 + 0.2 * k, 0.3 * (-1) ** k))
        image, clicked = synthetic_target(model, truth)
        write_png(root / f"im{k}.png", image)
        write_tlms(root / f"im{k}.tlms", [Landmark(n, (float(p[0]), float(p[1])), True)
                                          for n, p in clicked.items()])
        truths.append(truth)
        images.append(image)
        landmarks.append(clicked)
    return root, model, truths, images, landmarks


@pytest.fixture(scope="module")
def fitted(files):
    root = files[0]
    code = main(["fit", str(root / "im0.png"), str(root / "im1.png"), "--landmarks",
                 str(root / "im0.tlms"), str(root / "im1.tlms"), "--model", str(root / "small.h5"),
                 "-o", str(root / "out"), "--max-steps", "150", "--landmark-steps", "200",
                 "--warmup-steps", "100", "--serial", "--quiet", "--seed", "2"])
    return code, root / "out"


def test_the_result_folder_holds_both_photographs_and_one_albedo(files, fitted):
    _, model, truths, _, _ = files
    code, out = fitted
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["images"]) == 2 and "converged" in summary
    for k, truth in enumerate(truths):
        for name in ("target.png", "fit.png", "fit_landmarks.png", "best.rps", "mean.rps"):
            assert (out / f"image{k}" / name).is_file()
        mean = read_rps(out / f"image{k}" / "mean.rps")
        assert abs(mean.pose.yaw - truth.pose.yaw) < 0.05  # each photograph keeps its own pose
        assert summary["images"][k]["landmark_rmse_px"] < 2.0
    with np.load(out / "posterior.npz") as z:
        seen, visible = z["visible_images"], z["visible"]
        assert seen.shape == (2, model.n_vertices)
        np.testing.assert_array_equal(visible, seen.any(axis=0))
        np.testing.assert_array_equal(z["visible_count"], seen.sum(axis=0))
        # each photograph saw vertices the other did not (yaw +-0.3 rad)
        assert (seen[0] & ~seen[1]).any() and (seen[1] & ~seen[0]).any()
        assert z["diffuse_mean"].shape == (model.n_vertices, 3)
    with np.load(out / "samples.npz") as z:
        names = list(z["names"])
        assert names[:4] == [f"shape.{i}" for i in range(4)]
        assert "image1.pose.yaw" in names and "image0.pose.yaw" in names
        assert z["samples"].shape[0] == 2  # two chains
    for name in ("albedo_diffuse_frontal.png", "uncertainty_diffuse_frontal.png",
                 "seen_frontal.png", "traces.png", "config.json"):
        assert (out / name).is_file()


def test_chain_file_posterior_nc_and_report_describe_the_joint_fit(files, fitted):
    import arviz as az

    from mcmcfit.sampling.chain_file import read_chains_h5
    from mcmcfit.sampling.joint_layout import JointParamLayout
    from proposals.joint import JointParameter

    model = files[1]
    out = fitted[1]
    chains, layout, _ = read_chains_h5(out / "chain.h5")
    assert isinstance(layout, JointParamLayout) and layout.n_images == 2
    with np.load(out / "samples.npz") as z:
        assert list(z["names"]) == list(layout.names)
        np.testing.assert_array_equal(z["samples"][0], chains[0].stage2.samples[:z["samples"].shape[1]])
    best = chains[0].stage2.best_image.params
    assert isinstance(best, JointParameter)
    assert best.images[0].momo.albedo is best.images[1].momo.albedo  # one identity, read back
    assert abs(best.images[0].pose.yaw - YAWS[0]) < 0.1
    assert abs(best.images[1].pose.yaw - YAWS[1]) < 0.1

    idata = az.from_netcdf(out / "posterior.nc")
    post = idata.posterior
    assert post["pose"].dims == ("chain", "draw", "image", "pose_param")
    assert post["light"].dims[:3] == ("chain", "draw", "image")
    assert post["albedo"].dims == ("chain", "draw", "albedo_coefficient")  # shared: no image dim
    kept = chains[0].stage2.samples
    yaw = post["pose"].sel(image=1, pose_param="yaw").values[0]
    np.testing.assert_allclose(yaw, kept[:yaw.size, layout.index("image1.pose.yaw")])
    assert "template_rps_images" in post.attrs
    assert {"image0", "image1", "landmarks0", "landmarks1"} <= set(idata.observed_data.data_vars)
    assert az.summary(idata, var_names=["albedo"], kind="diagnostics").shape[0] == post["albedo"].shape[2]

    report = (out / "report.html").read_text()
    for name in ("image0/fit.png", "image1/target.png", "seen_frontal.png",
                 "uncertainty_diffuse_frontal.png"):
        assert f"src='{name}'" in report
    assert "Photographs (2, one identity)" in report
    assert (out / "mesh.ply").is_file()
    assert model.n_vertices == len(np.load(out / "posterior.npz")["visible"])


def test_bad_inputs_give_one_line_and_write_nothing(files, tmp_path, capsys):
    root = files[0]
    out = tmp_path / "never"
    args = ["fit", str(root / "im0.png"), str(root / "im1.png"), "--model", str(root / "small.h5"),
            "-o", str(out), "--quiet"]
    assert main([*args, "--landmarks", str(root / "im0.tlms")]) == 2
    assert "2 photograph(s) but 1 landmark file(s)" in capsys.readouterr().err
    assert main([*args, "--landmarks", str(root / "im0.tlms"), str(root / "im1.tlms"),
                 "--face-box", "1,1,20,20"]) == 2
    assert "needs landmarks, not --face-box" in capsys.readouterr().err
    assert main([*args, "--landmarks", str(root / "im0.tlms"), str(root / "missing.tlms")]) == 2
    assert "missing.tlms" in capsys.readouterr().err
    assert not out.exists()


def test_fit_joint_refuses_what_it_cannot_do(files):
    _, model, _, images, landmarks = files
    with pytest.raises(InputError, match="2 to 8 photographs, got 1"):
        fit_joint(images[:1], landmarks[:1], model)
    with pytest.raises(InputError, match="2 photographs but 1 landmark sets"):
        fit_joint(images, landmarks[:1], model)
    with pytest.raises(InputError, match="Gaussian sampler only"):
        fit_joint(images, landmarks, model, config=FitConfig(sampler="random-walk"))
    with pytest.raises(InputError, match="image 2 is entirely black"):
        fit_joint([images[0], np.zeros_like(images[1])], landmarks, model)
    with pytest.raises(InputError, match="image 1 has no landmarks"):
        fit_joint(images, [None, landmarks[1]], model)
