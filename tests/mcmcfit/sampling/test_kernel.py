"""The filter chain is a valid MH kernel (toy target, analytic moments); bookkeeping of the
filters; recorder; stage 1 recovers the pose of synthetic landmarks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from face_factory import scene, small_face_model

from albedo_model.camera import project
from albedo_model.params import Block, MoMoCoefficients, default_square, fit_to_image_size
from mcmcfit.sampling.chain import ChainRecorder
from mcmcfit.sampling.diagnostics import effective_sample_size
from mcmcfit.fitting.fit import fit
from mcmcfit.fitting.config import FitConfig
from mcmcfit.targets.landmarks import LandmarkGeometry
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.sampling.kernel import (
    IDENTITY, REJECTED_IMAGE, REJECTED_JOINT, REJECTED_LANDMARKS, REJECTED_PRIOR, init, run,
    step,
)
from proposals.base import mixture
from proposals.pose import FocalScaling, Rotation


def _norm(x, m, s):
    return -0.5 * math.log(2 * math.pi) - math.log(s) - 0.5 * ((x - m) / s) ** 2


LOG_F1, LOG_F2 = math.log(7.5), math.log(9.0)


class ToyTarget:
    """Three analytic factors of (yaw, f); a fake 'renderer' that counts its calls."""

    def __init__(self):
        self.renders = self.accepts = self.rejects = 0

    def log_lik_landmarks(self, p):
        return _norm(p.pose.yaw, 0.3, 0.4)

    def log_prior(self, p):  # a density over f (log-normal), so its -log f counts
        f = p.camera.focal_length
        return _norm(p.pose.yaw, 0.0, 0.5) + _norm(math.log(f), LOG_F1, 0.3) - math.log(f)

    def init_render(self, p):
        return ("accepted", p)

    def render(self, rs, p, touched):
        assert rs[0] == "accepted" and touched != Block.NONE
        self.renders += 1
        return ("candidate", p)

    def log_lik_image(self, rs):
        p = rs[1]
        return _norm(p.pose.yaw, -0.1, 0.6) + _norm(math.log(p.camera.focal_length), LOG_F2, 0.2)

    def accept(self, rs):
        self.accepts += 1
        return ("accepted", rs[1])

    def reject(self, rs):
        assert rs[0] == "candidate"
        self.rejects += 1


def _gauss_product(*pairs):
    prec = sum(1 / s**2 for _, s in pairs)
    return sum(m / s**2 for m, s in pairs) / prec, 1 / math.sqrt(prec)


class DropRatio:
    def __init__(self, inner):
        self.inner, self.name, self.touches = inner, inner.name, inner.touches

    def __call__(self, rng, state):
        return self.inner(rng, state)._replace(log_q_ratio=0.0)


def _toy_chain(proposal, n=30000, image=True, seed=0):
    target = ToyTarget()
    start = fit_to_image_size(default_square(), 32, 32)
    state = init(start, target, image=image)
    out = np.empty((n, 2))
    infos = []

    def cb(i, s, info):
        out[i] = s.params.pose.yaw, math.log(s.params.camera.focal_length)
        infos.append(info)

    run(np.random.default_rng(seed), state, target, proposal, n, image=image, callback=cb)
    return out[2000:], infos, target


def _assert_moments(x, mean, sd, z=5.0):
    ess, _ = effective_sample_size(x)
    assert ess > 1000
    assert abs(x.mean() - mean) < z * sd / math.sqrt(ess), (x.mean(), mean)
    assert abs(x.std() - sd) < z * sd / math.sqrt(2 * ess) * 1.5, (x.std(), sd)


def test_filter_chain_samples_the_product_posterior():
    prop = mixture((1.0, Rotation("yaw", 0.6)), (1.0, FocalScaling(0.25)))
    x, infos, target = _toy_chain(prop)
    yaw_mean, yaw_sd = _gauss_product((0.3, 0.4), (0.0, 0.5), (-0.1, 0.6))
    # in u = log f the prior is N(LOG_F1, 0.3) (Jacobian cancels) and the image factor N(LOG_F2, 0.2)
    lf_mean, lf_sd = _gauss_product((LOG_F1, 0.3), (LOG_F2, 0.2))
    _assert_moments(x[:, 0], yaw_mean, yaw_sd)
    _assert_moments(x[:, 1], lf_mean, lf_sd)
    # bookkeeping: rejections at each stage; renders only for moves past both filters
    codes = np.array([i.rejected_by for i in infos])
    assert {REJECTED_LANDMARKS, REJECTED_PRIOR, REJECTED_IMAGE} <= set(codes.tolist())
    assert target.renders == int(np.sum((codes == 0) | (codes == REJECTED_IMAGE)))
    assert target.accepts == int(np.sum(codes == 0)) and target.rejects == np.sum(codes == 3)
    assert all(i.accepted == (i.rejected_by == 0) for i in infos)


def test_dropping_the_proposal_ratio_biases_the_chain():
    """Negative control: the focal scaling's ratio is needed (bias 1/36 in log f)."""
    prop = mixture((1.0, Rotation("yaw", 0.6)), (1.0, DropRatio(FocalScaling(0.25))))
    x, _, _ = _toy_chain(prop)
    lf_mean, lf_sd = _gauss_product((LOG_F1, 0.3), (LOG_F2, 0.2))
    ess, _ = effective_sample_size(x[:, 1])
    assert abs(x[:, 1].mean() - (lf_mean - lf_sd**2)) < 5 * lf_sd / math.sqrt(ess)
    assert abs(x[:, 1].mean() - lf_mean) > 5 * lf_sd / math.sqrt(ess)  # expected bias ~7.5 SE


def test_landmark_stage_targets_landmarks_times_prior():
    prop = mixture((1.0, Rotation("yaw", 0.6)), (1.0, FocalScaling(0.5)))
    x, infos, target = _toy_chain(prop, image=False, n=20000, seed=1)
    assert target.renders == 0 and all(i.rejected_by != REJECTED_IMAGE for i in infos)
    yaw_mean, yaw_sd = _gauss_product((0.3, 0.4), (0.0, 0.5))
    _assert_moments(x[:, 0], yaw_mean, yaw_sd)
    _assert_moments(x[:, 1], LOG_F1, 0.3)


def test_identity_moves_and_minus_infinity_states():
    class Still:
        name, touches = "still", Block.POSE

        def __call__(self, rng, state):
            from proposals.base import no_move
            return no_move(state.params, self.name)

    target = ToyTarget()
    s0 = init(fit_to_image_size(default_square(), 8, 8), target)
    s1, info = step(np.random.default_rng(0), s0, target, Still())
    # an identity move is neither accepted nor rejected, renders nothing, draws no uniform
    assert s1 is s0 and not info.accepted and info.rejected_by == IDENTITY
    assert target.renders == 0
    # from a state whose image factor is -inf, a move to another -inf state is accepted
    stuck = s0._replace(log_lik_img=-math.inf)
    target.log_lik_image = lambda rs: -math.inf
    _s2, info = step(np.random.default_rng(3), stuck, target, Rotation("yaw", 1e-6))
    assert info.rejected_by != REJECTED_IMAGE


@pytest.mark.parametrize("ratio", [-math.inf, math.nan])
@pytest.mark.parametrize("joint", [True, False])
def test_a_move_refused_by_its_proposal_evaluates_nothing(joint, ratio):
    """A -inf or NaN proposal ratio (a diverged HMC trajectory, a point outside the move's
    coordinates) is rejected before any factor is read."""
    from proposals.base import Move

    class Refused:
        name, touches = "refused", Block.POSE

        def __call__(self, rng, state):
            bad = state.params._replace(pose=state.params.pose._replace(yaw=math.nan))
            return Move(bad, ratio, Block.POSE, self.name, joint=joint)

    target = ToyTarget()
    s0 = init(fit_to_image_size(default_square(), 8, 8), target)

    def explode(*_):
        raise AssertionError("a refused move was evaluated")

    target.log_lik_landmarks = target.log_prior = explode
    rng = np.random.default_rng(0)
    s1, info = step(rng, s0, target, Refused())
    assert s1 is s0 and not info.accepted and target.renders == 0
    assert info.rejected_by == (REJECTED_JOINT if joint else REJECTED_LANDMARKS)
    # no uniform is drawn for it
    assert rng.random() == np.random.default_rng(0).random()


def test_recorder_thins_and_tracks_best():
    target = ToyTarget()
    start = fit_to_image_size(default_square(), 32, 32)._replace(momo=MoMoCoefficients.zeros(2, 2, 1))
    layout = ParamLayout.for_params(start)
    state = init(start, target)
    rec = ChainRecorder(layout, 1000, 7, state, stage="image")
    prop = mixture((1.0, Rotation("yaw", 0.6)), (1.0, FocalScaling(0.25)))
    run(np.random.default_rng(0), state, target, prop, 1000, callback=rec)
    r = rec.record()
    assert r.samples.shape == (142, layout.size) and r.sample_step[0] == 6
    yaw = r.samples[:, layout.index("pose.yaw")]
    assert np.all(np.isfinite(yaw))
    assert r.best_image.log_lik_img == pytest.approx(max(r.log_lik_img.max(), state.log_lik_img))
    assert r.best_posterior.log_posterior >= r.log_posterior.max() - 1e-12
    stats = r.acceptance()
    assert sum(s.proposed for s in stats.values()) == 1000
    assert sum(s.accepted for s in stats.values()) == int(r.accepted.sum())
    back = layout.from_vector(layout.to_vector(r.best_image.params), start)
    assert back.pose == r.best_image.params.pose and back.camera == r.best_image.params.camera


def test_absorbed_recorders_equal_one_recorder_of_every_step():
    """Warm-up that absorbs later draws records exactly what one recorder of all steps would."""
    target = ToyTarget()
    start = fit_to_image_size(default_square(), 32, 32)._replace(momo=MoMoCoefficients.zeros(2, 2, 1))
    layout = ParamLayout.for_params(start)
    state = init(start, target)
    yaw_move = mixture((1.0, Rotation("yaw", 0.6)))
    both = mixture((1.0, Rotation("yaw", 0.6)), (1.0, FocalScaling(0.25)))
    whole = ChainRecorder(layout, 0, 3, state, stage="warmup")
    first = ChainRecorder(layout, 0, 3, state, stage="warmup")
    second = ChainRecorder(layout, 0, 3, state, stage="image")
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    s_a, s_b = state, state
    # the second part uses a proposal the first never did: its names must be re-indexed
    for n, prop, mine in ((99, yaw_move, first), (250, both, second)):  # thinning in phase
        off = whole.steps_done
        whole.extend(n)
        s_a = run(rng_a, s_a, target, prop, n,
                  callback=lambda i, st, info, off=off: whole(off + i, st, info))
        mine.extend(n)
        s_b = run(rng_b, s_b, target, prop, n, callback=mine)
    first.absorb(second)
    a, b = whole.record(), first.record()
    assert b.steps == a.steps == 349 and b.stage == "warmup"
    for name in ("sample_step", "samples", "log_prior", "log_lik_img", "accepted", "rejected_by"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert [a.proposal_names[i] for i in a.proposal] == [b.proposal_names[i] for i in b.proposal]
    assert b.best_image.step == a.best_image.step
    assert b.best_image.log_lik_img == a.best_image.log_lik_img


@pytest.fixture(scope="module")
def small_model():
    return small_face_model()


TRUE_POSE = {"yaw": 0.35, "pitch": -0.15, "roll": 0.06, "translation": (15.0, -10.0, -1100.0)}


def _landmark_clicks(model, params, noise, seed):
    geo = LandmarkGeometry(model)
    names = [n for n in geo.names if n != "center.back.of.head"]
    px, _ = project(geo.points(names, params), params.pose, params.view, params.camera,
                    params.image_size)
    vis = geo.visible(names, params)
    rng = np.random.default_rng(seed)
    return {n: p + rng.normal(0, noise, 2) for n, p, v in zip(names, px, vis) if v}


@pytest.mark.parametrize("sampler", ["mh", "emcee"])
def test_stage1_recovers_the_pose_of_synthetic_landmarks(small_model, sampler):
    truth = scene(256, 256, **TRUE_POSE)
    clicks = _landmark_clicks(small_model, truth, noise=1.0, seed=0)
    assert len(clicks) >= 9
    cfg = FitConfig(steps=0, landmark_steps=3000, chains=1, thin=5, init_pose="similarity",
                    stage1=sampler, sigma_lm=2.0, stage1_shape_weight=0.0)
    res = fit(np.full((256, 256, 3), 0.3), clicks, small_model, config=cfg, seed=4)
    assert res.template.pose.yaw == 0.0  # the chain, not the guess, found the angles
    best = res.best.params.pose
    for k in ("yaw", "pitch", "roll"):
        assert abs(getattr(best, k) - TRUE_POSE[k]) < math.radians(3), (k, getattr(best, k))
    post = res.get_chain(1, flat=True, discard=0.5)
    for k in ("yaw", "pitch"):
        assert abs(np.median(post[:, res.layout.index(f"pose.{k}")]) - TRUE_POSE[k]) < math.radians(4)


def test_face_box_stage_places_the_face_in_the_box(small_model):
    """No landmarks, only a box: the guess and the chain put the nose tip near the box centre
    and give the face the box's scale (the face-box likelihood's measures)."""
    truth = scene(128, 128, yaw=0.1, translation=(20.0, -15.0, -1000.0))
    clicks = _landmark_clicks(small_model, truth, noise=0.0, seed=0)
    eyes = 0.5 * (clicks["left.eye.corner_outer"] + clicks["right.eye.corner_outer"])
    span = np.linalg.norm(eyes - 0.5 * (clicks["left.lips.corner"] + clicks["right.lips.corner"]))
    nose = clicks["center.nose.tip"]
    half = 1.5 * span / math.sqrt(2)  # a square box of diagonal 3 x span around the nose
    box = (nose[0] - half, nose[1] - half, nose[0] + half, nose[1] + half)
    cfg = FitConfig(steps=0, landmark_steps=1000, chains=1, thin=5)
    res = fit(np.full((128, 128, 3), 0.3), None, small_model, config=cfg, seed=0, face_box=box)
    # the chosen start's chain: the other starts' short runs are not in its record
    assert 800 <= res.chains[0].stage1.steps <= 1000 and res.landmarks_used == ()
    geo = LandmarkGeometry(small_model)
    for p in (res.template, res.best.params):
        px, _ = project(geo.points(["center.nose.tip"], p), p.pose, p.view, p.camera, p.image_size)
        assert np.linalg.norm(px[0] - nose) < 0.1 * 2 * half * math.sqrt(2)
