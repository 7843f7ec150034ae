"""``mcmcfit fit`` and ``mcmcfit demo`` on the command line: outputs, progress, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.io.image_io import write_png
from albedo_model.io.momo_h5 import write_model_h5
from albedo_model.io.pts import IBUG68_TO_BASEL
from albedo_model.io.tlms import Landmark, write_tlms
from mcmcfit.cli import main

SHORT = ["--steps", "60", "--warmup-steps", "30", "--landmark-steps", "60", "--chains", "1"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A small model file, a 64 x 64 target PNG and its landmarks (TLMS and iBUG .pts)."""
    d = tmp_path_factory.mktemp("cli-fit")
    model = small_face_model()
    write_model_h5(model, d / "model.h5")
    image, clicks = synthetic_target(model, scene(64, 64, yaw=0.2))
    write_png(d / "face.png", image)
    write_tlms(d / "face.tlms", [Landmark(n, tuple(p), True) for n, p in clicks.items()]
               + [Landmark("made.up.point", (10.0, 10.0), True)])
    pts = np.full((68, 2), 30.0)
    for row, name in IBUG68_TO_BASEL.items():
        if name in clicks:
            pts[row] = clicks[name]
    body = "\n".join(f"{x + 1:.3f} {y + 1:.3f}" for x, y in pts)  # .pts files are 1-based
    (d / "face.pts").write_text(f"version: 1\nn_points: 68\n{{\n{body}\n}}\n")
    return d, clicks


def test_fit_writes_folder_with_progress_and_warning(files, capsys):
    d, clicks = files
    out = d / "out-tlms"
    code = main(["fit", str(d / "face.png"), "--landmarks", str(d / "face.tlms"),
                 "--model", str(d / "model.h5"), *SHORT, "--seed", "3", "-o", str(out)])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    assert "wrote" in cap.out and "report.html" in cap.out
    assert "chain 1/1 landmark stage" in cap.err and "chain 1/1 image stage" in cap.err
    assert "warning" in cap.err and "made.up.point" in cap.err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["seed"] == 3 and len(summary["model_sha256"]) == 64
    assert summary["landmarks"]["unknown"] == ["made.up.point"]
    assert set(summary["landmarks"]["used"]) == set(clicks)
    assert summary["steps"]["image"] == 60 and summary["steps"]["chains"] == 1
    assert (out / "report.html").is_file() and (out / "chain.h5").is_file()
    # --force replaces, without it an existing folder is an error (and stays untouched)
    before = (out / "summary.json").read_text()
    assert main(["fit", str(d / "face.png"), "--landmarks", str(d / "face.tlms"), "--model",
                 str(d / "model.h5"), *SHORT, "-o", str(out), "--quiet"]) == 2
    assert "exists" in capsys.readouterr().err
    assert (out / "summary.json").read_text() == before


def test_fit_with_ibug_pts_and_with_face_box(files, capsys):
    d, clicks = files
    out = d / "out-pts"
    assert main(["fit", str(d / "face.png"), "--landmarks", str(d / "face.pts"),
                 "--model", str(d / "model.h5"), *SHORT, "-o", str(out), "--quiet"]) == 0
    used = json.loads((out / "summary.json").read_text())["landmarks"]["used"]
    expected = {n for n in IBUG68_TO_BASEL.values() if n in clicks}
    assert len(expected) >= 3 and set(used) == expected
    # 1-based file coordinates are read back at the clicked (0-based) pixels: small error
    assert json.loads((out / "summary.json").read_text())["landmark_rmse_px"] < 3.0
    out = d / "out-box"
    assert main(["fit", str(d / "face.png"), "--face-box", "12,6,40,52", "--model",
                 str(d / "model.h5"), *SHORT, "-o", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["inputs"]["face_box"] == [12.0, 6.0, 52.0, 58.0]
    assert summary["landmark_rmse_px"] is None


def _fails_cleanly(capsys, argv, out, match):
    code = main(argv)
    err = capsys.readouterr().err
    assert code != 0
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("mcmcfit fit: error:"), err
    assert match in lines[0]
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}")]


def test_bad_inputs_give_one_line_and_write_nothing(files, tmp_path, capsys):
    d, clicks = files
    model = ["--model", str(d / "model.h5"), *SHORT, "--quiet"]
    out = tmp_path / "out"
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not a png at all")
    _fails_cleanly(capsys, ["fit", str(junk), "--landmarks", str(d / "face.tlms"), *model,
                            "-o", str(out)], out, "junk.png")
    black = tmp_path / "black.png"
    write_png(black, np.zeros((64, 64, 3)))
    _fails_cleanly(capsys, ["fit", str(black), "--landmarks", str(d / "face.tlms"), *model,
                            "-o", str(out)], out, "black")
    two = tmp_path / "two.tlms"
    names = list(clicks)[:2]
    write_tlms(two, [Landmark(n, tuple(clicks[n]), True) for n in names]
               + [Landmark("nobody.knows", (3.0, 4.0), True)])
    _fails_cleanly(capsys, ["fit", str(d / "face.png"), "--landmarks", str(two), *model,
                            "-o", str(out)], out, "two.tlms")
    _fails_cleanly(capsys, ["fit", str(d / "face.png"), "--face-box", "1,2,-3,4", *model,
                            "-o", str(out)], out, "face box")
    _fails_cleanly(capsys, ["fit", str(d / "face.png"), "--landmarks", str(d / "face.tlms"),
                            "--model", str(d / "model.h5"), "--steps", "-5", "-o", str(out)],
                   out, "steps")


def test_demo_prints_albedo_error(default_model_file, tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out), "--size", "64", "--steps", "40", "--warmup-steps", "20",
                 "--landmark-steps", "40", "--chains", "1", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "diffuse albedo: RMSE" in text and "coverage of the 90 % intervals" in text
    summary = json.loads((out / "summary.json").read_text())
    truth = summary["truth"]
    assert 0.0 <= truth["diffuse"]["rmse"] < 0.5 and 0.0 <= truth["diffuse"]["coverage"] <= 1.0
    assert f"{truth['diffuse']['rmse']:.4f}" in text
    for name in ("target.png", "truth.rps", "landmarks.tlms", "report.html", "posterior.npz"):
        assert (out / name).is_file()
    # the printed error is that of posterior.npz against the truth re-rendered from truth.rps
    from albedo_model.io.rps import read_rps
    from mcmcfit.jobs.model_spec import load_model_spec

    model = load_model_spec("default")
    true = read_rps(out / "truth.rps")
    post = np.load(out / "posterior.npz")
    true_diffuse = model.diffuse_instance(np.asarray(true.momo.albedo))
    vis = post["visible"]  # fitted view; the summary uses the true view: compare loosely
    rmse_fitted_view = np.sqrt(np.mean((post["diffuse_mean"][vis] - true_diffuse[vis]) ** 2))
    assert rmse_fitted_view == pytest.approx(truth["diffuse"]["rmse"], rel=0.2, abs=0.01)


def test_help_shows_the_fit_config_defaults():
    import argparse

    from mcmcfit.commands.fit import add_schedule_arguments
    from mcmcfit.fitting.config import FitConfig

    p = argparse.ArgumentParser()
    add_schedule_arguments(p)
    text = " ".join(p.format_help().split("options:", 1)[1].split())
    cfg = FitConfig()
    for option, value in (("--steps N", cfg.steps), ("--landmark-steps N", cfg.landmark_steps),
                          ("--chains K", cfg.chains)):
        assert f"{option} " in text and f"(default {value})" in text.split(option, 1)[1][:120]
