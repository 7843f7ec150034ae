"""Inputs that are not a face photograph fail fast, before any set-up or sampling, as InputError.

An image smaller than a face can be fitted to, target landmarks far outside the
image, a face of a few pixels (landmarks or face box): each is refused by
:func:`mcmcfit.fitting.initialisation.check_fit_inputs` at the start of ``fit``,
in well under a second, with a message naming the problem; on the command line
as one error line, exit code 2 and nothing written.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.errors import InputError
from albedo_model.io.image_io import write_png
from albedo_model.io.momo_h5 import write_model_h5
from albedo_model.io.tlms import Landmark, write_tlms
from mcmcfit.cli import main
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.fit import fit
from mcmcfit.fitting.initialisation import (
    MIN_FACE_PX,
    MIN_IMAGE_PX,
    OUTSIDE_MARGIN,
    check_fit_inputs,
)

#: A schedule that would take seconds: a bad input must be refused before it starts.
CFG = FitConfig(steps=200, landmark_steps=200, chains=2)
#: Well under a second for the check (the fit set-up alone takes longer).
FAST_S = 0.25


@pytest.fixture(scope="module")
def small_model():
    return small_face_model()


@pytest.fixture(scope="module")
def target(small_model):
    return synthetic_target(small_model, scene(64, 64, yaw=0.2))


def _refused(match: str, *args, **kwargs) -> str:
    t0 = time.perf_counter()
    with pytest.raises(InputError, match=match) as info:
        fit(*args, **kwargs)
    elapsed = time.perf_counter() - t0
    assert elapsed < FAST_S, f"refused after {elapsed:.2f} s"
    return str(info.value)


def test_too_small_image_is_refused_fast(small_model, target):
    _, clicks = target
    grey = np.full((1, 1, 3), 0.5)
    msg = _refused("1x1", grey, None, small_model, config=CFG, face_box=(0.0, 0.0, 1.0, 1.0))
    assert f"at least {MIN_IMAGE_PX}x{MIN_IMAGE_PX}" in msg
    _refused("16x40", np.full((40, 16, 3), 0.5), None, small_model, config=CFG)
    _refused("31x31", np.full((31, 31, 3), 0.5), clicks, small_model, config=CFG)


def test_landmarks_outside_the_image_are_refused_fast(small_model, target):
    image, clicks = target
    moved = {n: p + 500.0 for n, p in clicks.items()}  # e.g. landmarks of a larger image
    msg = _refused("outside the 64x64 image", image, moved, small_model, config=CFG)
    assert f"{len(clicks)} of {len(clicks)}" in msg and next(iter(clicks)) in msg
    one = dict(clicks)
    name = "center.chin.tip" if "center.chin.tip" in one else next(iter(one))
    one[name] = np.array([30.0, 200.0])
    msg = _refused(name, image, one, small_model, config=CFG)
    assert f"1 of {len(clicks)}" in msg and "(30, 200)" in msg
    # names the model does not know are ignored, wherever they are
    check_fit_inputs(64, 64, landmarks=dict(clicks, **{"no.such.point": (900.0, -900.0)}),
                     model_landmarks=small_model.landmark_vertices)


def test_landmarks_slightly_outside_the_image_are_fine(small_model, target):
    _, clicks = target
    margin = OUTSIDE_MARGIN * 64
    names = list(clicks)
    near = dict(clicks)
    near[names[0]] = np.array([-0.8 * margin, 10.0])
    near[names[1]] = np.array([30.0, 64.0 + 0.8 * margin])
    check_fit_inputs(64, 64, landmarks=near, model_landmarks=small_model.landmark_vertices)
    # ... but not when no landmark is inside the image at all
    edge = {n: np.array([-1.0 - 0.1 * i, 2.0 * i]) for i, n in enumerate(names)}
    with pytest.raises(InputError, match="none of the"):
        check_fit_inputs(64, 64, landmarks=edge, model_landmarks=small_model.landmark_vertices)


def test_a_face_of_a_few_pixels_is_refused_fast(small_model, target):
    image, clicks = target
    pts = np.array(list(clicks.values()))
    centre = pts.mean(axis=0)
    extent = float(np.ptp(pts, axis=0).max())
    tiny = {n: centre + (p - centre) * (0.6 * MIN_FACE_PX / extent) for n, p in clicks.items()}
    msg = _refused("span only", image, tiny, small_model, config=CFG)
    assert f"{MIN_FACE_PX:.0f} px" in msg
    _refused("only 5.0 px across", image, None, small_model, config=CFG,
             face_box=(30.0, 30.0, 35.0, 40.0))
    _refused("mostly outside the 64x64 image", image, None, small_model, config=CFG,
             face_box=(50.0, 50.0, 90.0, 90.0))
    _refused("face box must be", image, None, small_model, config=CFG,
             face_box=(10.0, 10.0, 5.0, 40.0))


def test_the_smallest_hard_case_passes_the_checks(default_model_file):
    """The 24-px-wide face of test_hard_cases is above every threshold."""
    from albedo_model.io.model_files import load_model
    from mcmcfit.jobs.synthetic_case import synthetic_case

    model = load_model(default_model_file)
    case = synthetic_case(model, seed=24, face_width_px=24)
    pts = np.array(list(case.landmarks.values()))
    assert np.ptp(pts, axis=0).max() > 1.5 * MIN_FACE_PX
    h, w = case.image.shape[:2]
    check_fit_inputs(w, h, landmarks=case.landmarks, model_landmarks=model.landmark_vertices)


@pytest.fixture(scope="module")
def files(tmp_path_factory, small_model, target):
    d = tmp_path_factory.mktemp("bad-inputs")
    write_model_h5(small_model, d / "model.h5")
    image, clicks = target
    write_png(d / "face.png", image)
    write_png(d / "dot.png", np.full((1, 1, 3), 0.5))
    write_tlms(d / "far.tlms", [Landmark(n, tuple(p + 300.0), True) for n, p in clicks.items()])
    return d, clicks


@pytest.mark.parametrize("case", ["1x1 image", "landmarks far outside", "tiny face box"])
def test_cli_refuses_with_one_line_exit_2_and_writes_nothing(files, tmp_path, capsys, case):
    d, clicks = files
    out = tmp_path / "out"
    argv, match = {
        "1x1 image": (["fit", str(d / "dot.png"), "--face-box", "0,0,1,1"], "1x1"),
        "landmarks far outside": (["fit", str(d / "face.png"), "--landmarks", str(d / "far.tlms")],
                                  next(iter(clicks))),
        "tiny face box": (["fit", str(d / "face.png"), "--face-box", "30,30,4,4"], "4.0 px across"),
    }[case]
    code = main([*argv, "--model", str(d / "model.h5"), "--steps", "500", "--quiet",
                 "-o", str(out)])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("mcmcfit fit: error:") and match in lines[0]
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]
