"""``--model-colour`` on fit, demo and batch; the colour space in model info, render, sample."""

from __future__ import annotations

import dataclasses
import json

import h5py
import numpy as np
import pytest
from colour_factory import srgb_case
from face_factory import scene, small_face_model

from albedo_model.io.colour_space import colour_space_metadata, decode_texture
from albedo_model.io.image_io import read_image, write_png
from albedo_model.io.momo_h5 import INFO_PATH, write_model_h5
from albedo_model.io.rps import write_rps
from albedo_model.io.tlms import Landmark, write_tlms
from albedo_model.render.renderer import render
from mcmcfit.cli import main


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """An sRGB-texture model file (colour space in its metadata), the same without, a photo."""
    d = tmp_path_factory.mktemp("cli-colour")
    case = srgb_case()
    write_model_h5(case.model, d / "srgb.h5")
    write_model_h5(dataclasses.replace(case.model, metadata={}), d / "plain.h5")
    (d / "images").mkdir()
    write_png(d / "images" / "face.png", case.image)
    write_tlms(d / "face.tlms", [Landmark(n, tuple(p), True) for n, p in case.clicks.items()])
    return d


# -- the option reaches every fit ---------------------------------------------------

@pytest.mark.parametrize("extra, expected", [([], None), (["--model-colour", "srgb"], "srgb"),
                                             (["--model-colour", "linear"], "linear")])
def test_fit_passes_the_option_to_the_config(files, monkeypatch, extra, expected):
    seen = {}

    def fake_run_fit_job(image, out, **kw):
        seen["config"] = kw["config"]
        return {"files": [], "timings": {}}

    monkeypatch.setattr("mcmcfit.jobs.fit_job.run_fit_job", fake_run_fit_job)
    assert main(["fit", str(files / "images" / "face.png"), "--quiet",
                 "-o", str(files / "never"), *extra]) == 0
    assert seen["config"].model_colour == expected


def test_bad_option_value_is_a_usage_error(files, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["fit", str(files / "images" / "face.png"), "-o", str(files / "x"),
              "--model-colour", "gamma"])
    assert exc.value.code == 2
    assert "--model-colour" in capsys.readouterr().err


def test_demo_passes_the_option_to_the_config(files, monkeypatch, tmp_path):
    seen = {}

    def fake_run_demo(out, **kw):
        seen["config"] = kw["config"]
        return {}

    monkeypatch.setattr("mcmcfit.jobs.fit_job.load_model_cached", lambda *a, **k: None)
    monkeypatch.setattr("mcmcfit.commands.demo.run_demo", fake_run_demo)
    monkeypatch.setattr("mcmcfit.commands.demo.format_demo_result", lambda out, s: "done")
    assert main(["demo", "-o", str(tmp_path / "demo"), "--quiet",
                 "--model-colour", "srgb"]) == 0
    assert seen["config"].model_colour == "srgb"


def test_batch_passes_the_option_through_its_options_to_every_task(files, monkeypatch, tmp_path):
    from mcmcfit.batch.run import BatchOptions, BatchResult, plan_batch

    seen = {}

    def fake_run_batch(opts):
        seen["opts"] = opts
        return BatchResult(0, 0, 0, [], 0)

    monkeypatch.setattr("mcmcfit.batch.run.run_batch", fake_run_batch)
    assert main(["batch", str(files / "images"), "-o", str(tmp_path / "batch"),
                 "--model", str(files / "plain.h5"), "--face-box-default", "--workers", "1",
                 "--quiet", "--model-colour", "srgb"]) == 0
    opts = seen["opts"]
    assert opts.model_colour == "srgb" and opts.config.model_colour == "srgb"
    tasks = plan_batch(opts).tasks
    assert len(tasks) == 1 and tasks[0].config["model_colour"] == "srgb"
    # the option of BatchOptions wins over the config's; None keeps the config's
    base = {"input": files / "images", "out": tmp_path / "b2",
            "model": str(files / "plain.h5"), "face_box": "lfw"}
    cfg = opts.config.replace(model_colour="linear")
    for colour, expected in ((None, "linear"), ("srgb", "srgb")):
        plan = plan_batch(BatchOptions(**base, config=cfg, model_colour=colour))
        assert plan.tasks[0].config["model_colour"] == expected


@pytest.mark.filterwarnings("ignore:the chains have NOT converged")
def test_fit_with_the_override_records_it_in_summary_json(files, capsys):
    out = files / "fit-override"
    code = main(["fit", str(files / "images" / "face.png"), "--landmarks",
                 str(files / "face.tlms"), "--model", str(files / "plain.h5"), "--steps", "60",
                 "--landmark-steps", "60", "--chains", "1", "--quiet",
                 "--model-colour", "srgb", "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["model"]["colour_space"] == "srgb"
    assert summary["model"]["colour_space_source"] == "override"
    assert summary["config"]["model_colour"] == "srgb"
    # the fitted render is in the photograph's encoded space: shown as is, not encoded again
    fit_png, target = read_image(out / "fit.png"), read_image(out / "target.png")
    face = np.any(np.abs(fit_png - target) > 0, axis=2)
    assert face.sum() > 100
    assert abs(fit_png[face].mean() - target[face].mean()) < 0.05


# -- model info, render, model sample ----------------------------------------------

def test_model_info_prints_the_resolved_colour_space(files, capsys, tmp_path):
    assert main(["model", "info", str(files / "srgb.h5"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["model_colour"]["value"] == "srgb"
    assert info["model_colour"]["source"] == "model metadata"
    # a MoMo file written elsewhere (no mcmcfit metadata): BFM's layout default
    foreign = tmp_path / "foreign.h5"
    write_model_h5(small_face_model(specular=False), foreign)
    with h5py.File(foreign, "a") as h5:
        del h5[INFO_PATH]
    assert main(["model", "info", str(foreign)]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith("colour space:"))
    assert "srgb" in line and "layout default" in line
    assert main(["model", "info", str(files / "plain.h5")]) == 0
    assert "colour space:  linear" in capsys.readouterr().out


def test_render_writes_an_srgb_texture_as_rendered(files, tmp_path, capsys):
    from albedo_model.io.model_files import load_model

    params = scene(48, 48, yaw=0.2)
    write_rps(tmp_path / "p.rps", params)
    model = load_model(files / "srgb.h5")
    plain = render(model, params, specular=False, gamma=False)
    encoded = render(model, params, specular=False, gamma=True)
    for name, extra in (("srgb", []), ("plain", ["--model-colour", "srgb"])):
        assert main(["render", str(files / f"{name}.h5"), str(tmp_path / "p.rps"),
                     "-o", str(tmp_path / f"{name}.png"), "--no-specular", *extra]) == 0
        img = read_image(tmp_path / f"{name}.png")
        assert np.allclose(img[plain.mask], plain.image[plain.mask], atol=1 / 255 + 1e-6)
    # a linear model is encoded for display, as before
    assert main(["render", str(files / "srgb.h5"), str(tmp_path / "p.rps"), "-o",
                 str(tmp_path / "lin.png"), "--no-specular", "--model-colour", "linear"]) == 0
    img = read_image(tmp_path / "lin.png")
    assert np.allclose(img[encoded.mask], encoded.image[encoded.mask], atol=1 / 255 + 1e-6)
    # --linear decodes an sRGB texture's render
    assert main(["render", str(files / "srgb.h5"), str(tmp_path / "p.rps"), "-o",
                 str(tmp_path / "dec.png"), "--no-specular", "--linear"]) == 0
    img = read_image(tmp_path / "dec.png")
    want = decode_texture(np.clip(plain.image, 0, 1))
    # (Pillow reads 16-bit RGB PNGs as 8-bit)
    assert np.allclose(img[plain.mask], want[plain.mask], atol=1 / 255 + 1e-6)
    capsys.readouterr()


def test_model_sample_does_not_encode_an_srgb_texture_twice(files):
    from albedo_model.io.model_files import load_model
    from mcmcfit.commands.model_sample import sample_faces

    model = load_model(files / "srgb.h5")
    def rng():
        return np.random.default_rng(3)

    as_srgb, masks, _ = sample_faces(model, 2, rng(), size=32)
    as_linear, _, _ = sample_faces(model, 2, rng(), size=32, model_colour="linear")
    # the linear reading applies the display gamma (1/2.2); the sRGB one shows values as rendered
    assert np.allclose(as_linear[masks] ** 2.2, as_srgb[masks], atol=1e-4)
    assert not np.allclose(as_linear[masks], as_srgb[masks], atol=1e-2)
    model_md = dataclasses.replace(model, metadata=colour_space_metadata("linear"))
    again, _, _ = sample_faces(model_md, 2, rng(), size=32)
    assert np.array_equal(again, as_linear)
