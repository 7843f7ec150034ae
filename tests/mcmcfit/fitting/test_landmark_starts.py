"""The landmark stage from several starts (:mod:`mcmcfit.fitting.landmark_starts`).

Three kinds of check:

* the mechanism, against a known truth: a toy landmark factor with two modes
  (the true one and a trap 3 nats lower: the mirrored yaw, a near distance, or
  frontal for a face at 25 deg) and a proposal of small steps that cannot cross
  between them. From a guess in the trap a single chain stays there in every
  seed (the control); the several starts find the true mode in every seed;
* the starts themselves (mirrored / side yaws, distance and focal length scaled
  together, the face kept where it was in the image) and the bookkeeping
  (steps add up to the budget, one start chosen, deterministic, one start is
  today's chain);
* the five synthetic faces of the default model (seeds 0-4, as in
  ``test_fit_accuracy``), two chain seeds each: the stage's best pose within
  3 deg of the truth in yaw, pitch and roll. Faces 3 and 4 do not meet it, for
  reasons no start can fix (see :data:`NOT_YET`); they are expected failures.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from face_factory import scene, small_face_model

from albedo_model.camera import project
from albedo_model.io.model_files import load_model
from albedo_model.params import ImageSize
from albedo_model.render.renderer import Renderer
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.initialisation import initial_params, pose_from_landmarks
from mcmcfit.fitting.landmark_starts import (
    DISTANCE_FACTORS,
    SIDE_YAW_DEG,
    build_starts,
    landmark_stage,
)
from mcmcfit.jobs.synthetic_case import synthetic_case
from mcmcfit.sampling.chain import ChainRecorder
from mcmcfit.sampling.kernel import init, run
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.targets.face import FaceTarget
from mcmcfit.targets.landmarks import LandmarkGeometry, LandmarkTarget
from mcmcfit.targets.priors import LogPrior
from proposals.base import mixture
from proposals.pose import Distance, Rotation
from proposals.schedule import CENTERING_LANDMARKS, landmark_stage_proposal

SEEDS = (0, 1, 2, 3, 4)


def _distance(p) -> float:
    return float(p.view.translation[2] - p.pose.translation[2])


# -- a toy landmark factor with a trap ------------------------------------------------------


class TwoModes:
    """Landmark factor ``log(N(true) + e^-3 N(trap))`` over yaw (rad) and distance (mm).

    Each mode is a Gaussian with sd 0.03 rad in yaw and 25 mm in distance; no prior.
    """

    landmarks = None

    def __init__(self, true_mode, trap):
        self.modes = ((0.0, true_mode), (-3.0, trap))

    def log_prior(self, params) -> float:
        return 0.0

    def log_lik_landmarks(self, params) -> float:
        yaw, d = float(params.pose.yaw), _distance(params)
        terms = [w - 0.5 * ((yaw - m[0]) / 0.03) ** 2 - 0.5 * ((d - m[1]) / 25.0) ** 2
                 for w, m in self.modes]
        return float(np.logaddexp(*terms))


#: (true mode, trap) in (yaw rad, distance mm); the guess sits in the trap.
TRAPS = {
    "mirrored": ((0.35, 1000.0), (-0.35, 1000.0)),
    "near": ((0.35, 1000.0), (0.35, 1000.0 * DISTANCE_FACTORS["near"])),
    "frontal": ((math.radians(SIDE_YAW_DEG), 1000.0), (0.0, 1000.0)),
}


def _local_proposal():
    """Small yaw and distance steps only: no move crosses from a trap to the true mode."""
    return mixture((0.5, Rotation("yaw", 0.02)), (0.5, Distance(5.0)), name="local")


def _trap_guess(trap):
    return scene(64, 64, yaw=trap[0], translation=(0.0, 0.0, -trap[1]),
                 focal=7.5 * trap[1] / 1000.0)


def _in_mode(params, mode) -> bool:
    return abs(params.pose.yaw - mode[0]) < 0.1 and abs(_distance(params) - mode[1]) < 100.0


@pytest.mark.parametrize("kind", sorted(TRAPS))
def test_several_starts_leave_a_trap_a_single_chain_stays_in(kind):
    """Single chain from the trap: stays in it in every seed; several starts: the true mode."""
    true_mode, trap = TRAPS[kind]
    target, guess = TwoModes(true_mode, trap), _trap_guess(trap)
    layout = ParamLayout.for_params(guess)
    single_found, multi_found = [], []
    for seed in SEEDS:
        rec, _ = landmark_stage(np.random.default_rng(seed), guess, target, _local_proposal(),
                                1000, layout=layout, thin=10, starts=("guess",))
        single_found.append(_in_mode(rec.best_posterior.params, true_mode))
        rec, info = landmark_stage(np.random.default_rng(seed), guess, target,
                                   _local_proposal(), 1000, layout=layout, thin=10)
        multi_found.append(_in_mode(rec.best_posterior.params, true_mode))
        assert info["chosen"] != "guess", info
    assert sum(single_found) <= 1, single_found  # the control: stuck (measured: 5 of 5 stuck)
    assert all(multi_found), multi_found


class FlatRidge:
    """The real prior, and a likelihood of the yaw alone (flat along the distance ridge)."""

    landmarks = None

    def __init__(self):
        self.prior = LogPrior()

    def log_prior(self, params) -> float:
        return self.prior(params)

    def log_lik_landmarks(self, params) -> float:
        return -0.5 * ((float(params.pose.yaw) - 0.35) / 0.03) ** 2


def test_the_prior_jacobian_does_not_pull_the_choice_near():
    """On a likelihood flat in distance, the near start must not win by ``-log d - log f``."""
    target = FlatRidge()
    guess = scene(64, 64, yaw=0.35, translation=(0.0, 0.0, -1000.0))
    near = build_starts(guess, kinds=("near",))[0].params
    # the bias exists: in (t_z, f) the near start has the higher log posterior
    assert target.log_prior(near) > target.log_prior(guess) + 0.5
    layout = ParamLayout.for_params(guess)
    chosen = [landmark_stage(np.random.default_rng(seed), guess, target, _local_proposal(), 1000,
                             layout=layout, thin=10)[1]["chosen"] for seed in SEEDS]
    assert chosen.count("near") == 0, chosen


def test_starts_are_recorded_and_the_budget_is_kept():
    true_mode, trap = TRAPS["mirrored"]
    target, guess = TwoModes(true_mode, trap), _trap_guess(trap)
    layout = ParamLayout.for_params(guess)
    calls = []
    rec, info = landmark_stage(np.random.default_rng(3), guess, target, _local_proposal(), 1003,
                               layout=layout, thin=10, progress=lambda d, t: calls.append((d, t)))
    starts = info["starts"]
    assert [s["name"] for s in starts] == ["guess", "mirrored", "near", "far"]
    assert sum(s["chosen"] for s in starts) == 1
    chosen = next(s for s in starts if s["chosen"])
    assert chosen["name"] == info["chosen"] == "mirrored"
    assert info["short_steps"] == int(0.2 * 1003) // 4
    assert sum(s["steps"] for s in starts) == 1003
    assert rec.steps == chosen["steps"] == 1003 - 3 * info["short_steps"]
    assert len(rec.log_prior) == rec.steps and rec.samples.shape[0] == rec.steps // 10
    assert chosen["score"] == max(s["score"] for s in starts)
    assert calls[-1] == (1003, 1003)
    assert json.loads(json.dumps(rec.extra, default=float))["starts"][1]["name"] == "mirrored"
    # deterministic given the generator
    again, info2 = landmark_stage(np.random.default_rng(3), guess, target, _local_proposal(),
                                  1003, layout=layout, thin=10)
    assert info2["starts"] == starts
    np.testing.assert_array_equal(again.log_posterior, rec.log_posterior)
    np.testing.assert_array_equal(again.samples, rec.samples)


def test_bad_start_kinds_are_refused():
    with pytest.raises(ValueError, match="start kinds"):
        build_starts(scene(), kinds=("guess", "sideways"))
    with pytest.raises(ValueError, match="start kinds"):
        build_starts(scene(), kinds=("guess", "guess"))


# -- the starts on a real landmark factor ---------------------------------------------------


@pytest.fixture(scope="module")
def small_model():
    return small_face_model()


def _small_target(model, truth):
    """Landmark-only target whose clicks are the exact visible projections of ``truth``."""
    geometry = LandmarkGeometry(model)
    names = geometry.names
    px, _ = project(geometry.points(names, truth), truth.pose, truth.view, truth.camera,
                    truth.image_size)
    visible = geometry.visible(names, truth)
    clicks = {n: p for n, p, v in zip(names, px, visible) if v}
    factor = LandmarkTarget(geometry, clicks, image_size=ImageSize(128, 128))
    return FaceTarget(Renderer(model, threads=1), None, factor, LogPrior()), factor


def _landmark_box(factor, p) -> tuple[np.ndarray, float]:
    px, _ = project(factor.geometry.points(factor.names, p), p.pose, p.view, p.camera,
                    p.image_size)
    return px.mean(axis=0), float(np.sqrt(np.prod(np.ptp(px, axis=0))))


@pytest.mark.embree
@pytest.mark.parametrize("yaw_deg", [20.0, 3.0])
def test_starts_keep_the_face_in_place(small_model, yaw_deg):
    """Mirrored or side yaws, distance x 0.6 / x 1.6 with the same image size and centre."""
    truth = scene(128, 128, yaw=math.radians(yaw_deg), translation=(20.0, -10.0, -1000.0),
                  coefficients=None)
    target, factor = _small_target(small_model, truth)
    starts = build_starts(truth, target)
    names = [s.name for s in starts]
    if yaw_deg >= 10.0:
        assert names == ["guess", "mirrored", "near", "far"]
        assert starts[1].params.pose.yaw == pytest.approx(-truth.pose.yaw)
    else:
        assert names == ["guess", f"yaw+{SIDE_YAW_DEG:g}", f"yaw-{SIDE_YAW_DEG:g}", "near", "far"]
        assert [math.degrees(s.params.pose.yaw) for s in starts[1:3]] == pytest.approx(
            [SIDE_YAW_DEG, -SIDE_YAW_DEG])
    assert starts[0].params == truth
    centre0, size0 = _landmark_box(factor, truth)
    for s in starts[1:]:
        centre, size = _landmark_box(factor, s.params)
        assert np.abs(centre - centre0).max() < 0.5, s.name
        if s.name in DISTANCE_FACTORS:
            k = DISTANCE_FACTORS[s.name]
            assert _distance(s.params) == pytest.approx(k * _distance(truth))
            assert s.params.camera.focal_length == pytest.approx(k * truth.camera.focal_length)
            assert s.params.pose.yaw == truth.pose.yaw
            # the same image size up to perspective (a 180 mm deep head at 0.6 m and 1.6 m)
            assert size == pytest.approx(size0, rel=0.05), s.name


@pytest.mark.embree
def test_one_start_is_todays_landmark_stage(small_model):
    truth = scene(128, 128, yaw=0.3, translation=(0.0, 0.0, -1000.0))
    target, factor = _small_target(small_model, truth)
    start = truth._replace(pose=truth.pose._replace(yaw=0.1))
    layout = ParamLayout.for_params(start)
    proposal = landmark_stage_proposal(factor.geometry.point, shape_weight=0.5)
    rec, info = landmark_stage(np.random.default_rng(5), start, target, proposal, 300,
                               layout=layout, thin=10, starts=("guess",))
    state = init(start, target, image=False)
    recorder = ChainRecorder(layout, 300, 10, state, stage="landmarks")
    run(np.random.default_rng(5), state, target, proposal, 300, image=False, callback=recorder)
    ref = recorder.record()
    assert [s["name"] for s in info["starts"]] == ["guess"] and info["short_steps"] == 0
    np.testing.assert_array_equal(rec.log_posterior, ref.log_posterior)
    np.testing.assert_array_equal(rec.samples, ref.samples)
    assert rec.best_posterior.step == ref.best_posterior.step


# -- the five synthetic faces -----------------------------------------------------------------

#: Faces whose landmark-stage pose is not within 3 deg yet, and why (measured over 5 chain
#: seeds at the default 5,000 steps, single start vs these starts).
NOT_YET = {
    3: "the landmark posterior itself puts the face off: its maximum (Powell over pose, focal "
       "length and shape) is 3.7 deg off (yaw +3.3, at 495 mm), and the guess, which the best "
       "sample stays at in every seed with one or several starts, 5.6 deg (pitch)",
    4: "right.lips.corner is hidden on the mean shape at the true pose (a lip bulge 2.3-7.6 mm "
       "in front of it: 9.4 nats); yaws 10-15 deg off, where it is visible, are the posterior's "
       "higher mode (one start: 3 of 5 seeds there, several: 4 of 5). With visibility rays "
       "starting 10 mm in front of a landmark: 3.2 deg in 5 of 5 seeds (the guess)",
}


@pytest.fixture(scope="module")
def default_model(default_model_file):
    return load_model(default_model_file)


@pytest.fixture(scope="module")
def default_renderer(default_model):
    return Renderer(default_model, threads=1)


def _face_stage(model, renderer, case, seed: int, n_steps: int):
    """The landmark stage of ``fit`` on a synthetic case (set up as ``fit`` does), 4 starts."""
    cfg = FitConfig()
    geometry = LandmarkGeometry(model)
    factor = LandmarkTarget(geometry, case.landmarks, sigma=cfg.sigma_lm,
                            image_size=ImageSize(250, 250),
                            hidden_probability=cfg.lm_hidden_probability)
    params0 = pose_from_landmarks(geometry, factor.names, factor.observed,
                                  initial_params(model, 250, 250))
    target = FaceTarget(renderer, None, factor, LogPrior(cfg.prior))
    centring = geometry.point if all(n in geometry.names for n in CENTERING_LANDMARKS) else None
    proposal = landmark_stage_proposal(centring, shape_weight=cfg.stage1_shape_weight,
                                       block_size=cfg.block_size)
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0])  # fit's chain 0
    return landmark_stage(rng, params0, target, proposal, n_steps,
                          layout=ParamLayout.for_params(params0), thin=cfg.thin)


@pytest.mark.embree
@pytest.mark.parametrize("face", [
    pytest.param(f, marks=pytest.mark.xfail(reason=NOT_YET[f], strict=False)) if f in NOT_YET
    else f for f in SEEDS])
def test_landmark_stage_within_3_degrees_on_the_five_faces(default_model, default_renderer, face):
    case = synthetic_case(default_model, seed=face)
    t = case.truth.pose
    for seed in (0, 1):
        rec, info = _face_stage(default_model, default_renderer, case, seed, 1500)
        p = rec.best_posterior.params.pose
        err = [math.degrees(abs(getattr(p, a) - getattr(t, a))) for a in ("yaw", "pitch", "roll")]
        assert max(err) < 3.0, (seed, err, info["chosen"])
