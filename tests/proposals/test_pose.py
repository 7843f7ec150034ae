"""Pose and camera proposals: stationarity of MH chains, image centring, errors."""

from __future__ import annotations

import numpy as np
import pytest
from mh_chain import (
    DropRatio,
    assert_moments,
    base_state,
    changed_blocks,
    moment_errors,
    random_state,
    run_chain,
)
from scipy import stats

from albedo_model.camera import project
from albedo_model.errors import InputError
from albedo_model.params import Block
from proposals.base import mixture
from proposals.coefficients import CoefficientWalk
from proposals.pose import Distance, FocalScaling, ImageCentered, Rotation, Translation
from proposals.schedule import pose_proposal
from proposals.base import ProposalState

N = 12_000


def _norm_logpdf(x, m, s):
    return -0.5 * ((x - m) / s) ** 2


def test_rotation_chain_matches_gaussian_angles():
    target = {"yaw": (0.1, 0.2), "pitch": (-0.1, 0.3), "roll": (0.05, 0.1)}
    prop = mixture(*((1.0, Rotation(a, 2 * s)) for a, (_, s) in target.items()))

    def log_p(p):
        return sum(_norm_logpdf(getattr(p.pose, a), m, s) for a, (m, s) in target.items())

    samples, acc = run_chain(prop, log_p, base_state(),
                             lambda p: [p.pose.yaw, p.pose.pitch, p.pose.roll], N, seed=1)
    assert 0.3 < acc < 0.95
    assert_moments(samples, [m for m, _ in target.values()], [s for _, s in target.values()])


def test_translation_chain_matches_gaussian():
    def log_p(p):
        tx, ty, _ = p.pose.translation
        return _norm_logpdf(tx, 5.0, 20.0) + _norm_logpdf(ty, -3.0, 10.0)

    samples, _ = run_chain(Translation(12.0), log_p, base_state(),
                           lambda p: p.pose.translation, N, seed=2)
    assert_moments(samples[:, :2], [5.0, -3.0], [20.0, 10.0])
    assert np.all(samples[:, 2] == base_state().pose.translation[2])  # t_z is kept


LOG_F0 = np.log(7.5)


def _lognormal_focal(p, mu=LOG_F0, s=0.3):
    f = p.camera.focal_length
    return _norm_logpdf(np.log(f), mu, s) - np.log(f)  # log-normal density in f


def test_focal_scaling_chain_matches_lognormal_and_needs_its_ratio():
    prop = mixture((0.5, FocalScaling(0.3)), (0.5, FocalScaling(0.1)))
    feat = lambda p: [np.log(p.camera.focal_length)]  # noqa: E731
    samples, _ = run_chain(prop, _lognormal_focal, base_state(), feat, N, seed=3)
    assert_moments(samples, np.log(7.5), 0.3)
    wrong, _ = run_chain(DropRatio(prop), _lognormal_focal, base_state(), feat, N // 2, seed=3)
    assert moment_errors(wrong, np.log(7.5), 0.3).max() > 0.15


def _distance(p):
    return p.view.translation[2] - p.pose.translation[2]


def _fibre_target(g_logpdf):
    """Density g(d) h(f/d) / d in (t_z, f) (h = 1): d ~ g along a fixed f/d fibre."""
    return lambda p: g_logpdf(_distance(p)) - np.log(_distance(p))


def test_distance_chain_has_jacobian_d():
    start = base_state()._replace(pose=base_state().pose._replace(translation=(0.0, 0.0, -400.0)))
    log_p = _fibre_target(lambda d: _norm_logpdf(d, 400.0, 100.0))
    samples, acc = run_chain(Distance(80.0), log_p, start,
                             lambda p: [_distance(p), p.camera.focal_length / _distance(p)],
                             N, seed=4)
    assert acc > 0.3
    assert_moments(samples[:, :1], 400.0, 100.0)
    # f / d is invariant: the image size of the face is kept
    np.testing.assert_allclose(samples[:, 1], 7.5 / 400.0, rtol=1e-12)
    wrong, _ = run_chain(DropRatio(Distance(80.0)), log_p, start, lambda p: [_distance(p)], N // 2,
                         seed=4)
    assert moment_errors(wrong, 400.0, 100.0).max() > 0.15


def test_distance_reflection_at_the_lower_bound():
    """A target with much mass near d = 1: reflection keeps the chain exact (truncated normal)."""
    m, s = 30.0, 40.0
    start = base_state()._replace(pose=base_state().pose._replace(translation=(0.0, 0.0, -30.0)))
    log_p = _fibre_target(lambda d: _norm_logpdf(d, m, s) if d > 1.0 else -np.inf)
    samples, _ = run_chain(Distance(30.0), log_p, start, lambda p: [_distance(p)], N, seed=5)
    assert samples.min() > 1.0
    truth = stats.truncnorm((1.0 - m) / s, np.inf, loc=m, scale=s)
    assert_moments(samples, truth.mean(), truth.std())


def test_distance_and_focal_jointly_sample_the_product_target():
    start = base_state()._replace(pose=base_state().pose._replace(translation=(0.0, 0.0, -600.0)))

    def log_p(p):
        return _norm_logpdf(_distance(p), 600.0, 100.0) + _lognormal_focal(p)

    prop = mixture((1.0, Distance(100.0)), (1.0, FocalScaling(0.25)))
    feat = lambda p: [_distance(p), np.log(p.camera.focal_length)]  # noqa: E731
    samples, _ = run_chain(prop, log_p, start, feat, N, seed=6)
    assert_moments(samples, [600.0, np.log(7.5)], [100.0, 0.3])


def test_distance_rejects_a_state_behind_the_bound():
    p = base_state()._replace(pose=base_state().pose._replace(translation=(0.0, 0.0, -0.5)))
    with pytest.raises(InputError, match="in front of the camera"):
        Distance(5.0)(np.random.default_rng(0), ProposalState(p))


def _anchor(p):
    """A landmark-like point that depends on the shape coefficients."""
    return np.array([35.0, 30.0, 80.0]) + 5.0 * np.asarray(p.momo.shape[:3])


def _pixel(p):
    px, _ = project(_anchor(p)[None], p.pose, p.view, p.camera, p.image_size)
    return px[0]


def test_image_centered_keeps_the_anchor_pixel():
    rng = np.random.default_rng(7)
    props = [ImageCentered(Rotation(a, 0.3), _anchor) for a in ("yaw", "pitch", "roll")]
    props += [ImageCentered(Distance(200.0), _anchor), ImageCentered(FocalScaling(0.2), _anchor),
              ImageCentered(CoefficientWalk(Block.SHAPE, 0.5, index=slice(0, 3)), _anchor)]
    for prop in props:
        assert prop.touches == prop.inner.touches | Block.CAMERA
        for _ in range(40):
            p = random_state(rng)
            move = prop(rng, ProposalState(p))
            assert np.isfinite(move.log_q_ratio)
            assert changed_blocks(p, move.params) & Block.CAMERA
            np.testing.assert_allclose(_pixel(move.params), _pixel(p), atol=1e-8)


def test_image_centered_ratio_and_state_are_the_inner_ones():
    inner = mixture((1.0, Distance(100.0)), (1.0, FocalScaling(0.1)), (1.0, Rotation("yaw", 0.2)))
    wrapped = ImageCentered(inner, _anchor, label="lm")
    p = random_state(np.random.default_rng(8))
    for seed in range(20):
        a = inner(np.random.default_rng(seed), ProposalState(p))
        b = wrapped(np.random.default_rng(seed), ProposalState(p))
        assert b.log_q_ratio == a.log_q_ratio and b.name == a.name + "@lm"
        assert b.params.pose == a.params.pose
        assert b.params.camera.focal_length == a.params.camera.focal_length
        assert b.touched == a.touched | Block.CAMERA


def test_image_centered_chain_with_a_principal_point_target():
    """Centred focal scaling: the chain lives on pp = C - a f; compare with quadrature."""
    p0 = base_state()  # pose at (0, 0, -1000), no rotation: anchor eye coords (35, 30, -920)
    anchor = lambda p: np.array([35.0, 30.0, 80.0])  # noqa: E731
    depth = 1000.0 - 80.0
    s_x, s_y = p0.camera.sensor_size
    a_x, a_y = 2 * 35.0 / (s_x * depth), 2 * 30.0 / (s_y * depth)  # d pp / d f (x: -, y: -)
    f0 = p0.camera.focal_length
    c_x, c_y = a_x * f0, a_y * f0  # pp = (c_x - a_x f, c_y - a_y f), pp(f0) = 0

    def log_p(p):
        ppx, ppy = p.camera.principal_point
        return (_lognormal_focal(p, s=0.2) + _norm_logpdf(ppx, 0.0, 0.1)
                + _norm_logpdf(ppy, 0.0, 0.1))

    prop = ImageCentered(mixture((1.0, FocalScaling(0.2)), (1.0, FocalScaling(0.05))), anchor)
    samples, _ = run_chain(prop, log_p, p0, lambda p: [p.camera.focal_length,
                                                         *p.camera.principal_point], N // 2, seed=9)
    np.testing.assert_allclose(samples[:, 1], c_x - a_x * samples[:, 0], atol=1e-12)
    np.testing.assert_allclose(samples[:, 2], c_y - a_y * samples[:, 0], atol=1e-12)
    # truth: density of f along the curve (a shear, unit Jacobian) on a fine grid
    f = np.linspace(1.0, 30.0, 200_001)
    logd = (_norm_logpdf(np.log(f), np.log(7.5), 0.2) - np.log(f)
            + _norm_logpdf(c_x - a_x * f, 0, 0.1) + _norm_logpdf(c_y - a_y * f, 0, 0.1))
    w = np.exp(logd - logd.max())
    w /= w.sum()
    lf = np.log(f)
    mean = (w * lf).sum()
    std = np.sqrt((w * (lf - mean) ** 2).sum())
    assert std < 0.19  # the pp factor does constrain f
    assert_moments(np.log(samples[:, :1]), mean, std)


def test_image_centered_returns_rejection_when_anchor_unprojectable():
    p = base_state()
    bad = ImageCentered(Rotation("yaw", 0.1), lambda q: np.array([np.nan, 0.0, 0.0]))
    move = bad(np.random.default_rng(0), ProposalState(p))
    assert move.log_q_ratio == -np.inf
    assert move.params.camera == p.camera


def test_pose_proposal_structure():
    prop = pose_proposal(lambda name, p: np.zeros(3))
    assert prop.touches == Block.POSE | Block.CAMERA
    np.testing.assert_allclose(prop.weights, np.array([1, 1, 1, 1, 0.2]) / 4.2)
    uncentred = pose_proposal(None)
    np.testing.assert_allclose(uncentred.weights, np.array([4.0, 0.2]) / 4.2)
