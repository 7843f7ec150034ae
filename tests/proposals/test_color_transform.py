"""Colour-transform walk: gain, contrast and offset all move; exact log-normal gain ratio."""

from __future__ import annotations

import numpy as np
import pytest
from mh_chain import DropRatio, assert_moments, base_state, moment_errors, run_chain

from albedo_model.errors import InputError
from albedo_model.params import Block, ColorTransform
from proposals.base import mixture
from proposals.color_transform import ColorTransformWalk
from proposals.base import ProposalState

N = 12_000


def test_gain_contrast_and_offset_all_move():
    """The reference discards gain and contrast updates; here every part changes."""
    p = base_state()
    move = ColorTransformWalk(0.01, 0.01, 1e-4)(np.random.default_rng(0), ProposalState(p))
    ct = move.params.color_transform
    assert move.touched == Block.COLOR_TRANSFORM
    assert all(g != 1.0 for g in ct.gain) and ct.contrast != 1.0
    assert all(o != 0.0 for o in ct.offset)
    assert move.log_q_ratio == pytest.approx(np.sum(np.log(ct.gain)), rel=1e-12)
    assert p.color_transform == ColorTransform()


def test_zero_sigmas_keep_their_part():
    p = base_state()
    ct = ColorTransformWalk(0.0, 0.0, 0.1)(np.random.default_rng(1), ProposalState(p)).params.color_transform
    assert ct.gain == (1.0, 1.0, 1.0) and ct.contrast == 1.0 and ct.offset != (0.0, 0.0, 0.0)
    with pytest.raises(InputError):
        ColorTransformWalk(0.0, 0.0, 0.0)
    with pytest.raises(InputError):
        ColorTransformWalk(-0.1, 0.0, 0.0)


MU_G, S_G = np.log([1.2, 0.9, 1.0]), np.array([0.3, 0.2, 0.25])
M_C, S_C = 0.8, 0.1
M_O, S_O = np.array([0.02, -0.01, 0.0]), np.array([0.03, 0.025, 0.03])


def _log_p(p):
    ct = p.color_transform
    g, o = np.asarray(ct.gain), np.asarray(ct.offset)
    if np.any(g <= 0):
        return -np.inf
    lg = np.log(g)
    return float(-0.5 * np.sum(((lg - MU_G) / S_G) ** 2) - np.sum(lg)  # log-normal in g
                 - 0.5 * ((ct.contrast - M_C) / S_C) ** 2 - 0.5 * np.sum(((o - M_O) / S_O) ** 2))


def _feat(p):
    ct = p.color_transform
    return [*np.log(ct.gain), ct.contrast, *ct.offset]


def test_colour_chain_matches_lognormal_gain_and_gaussian_contrast_offset():
    prop = mixture((1.0, ColorTransformWalk(0.15, 0.05, 0.015)),  # all parts together
                   (2.0, ColorTransformWalk(0.4, 0.0, 0.0)),
                   (1.0, ColorTransformWalk(0.0, 0.2, 0.0)),
                   (2.0, ColorTransformWalk(0.0, 0.0, 0.04)))
    truth = ([*MU_G, M_C, *M_O], [*S_G, S_C, *S_O])
    samples, acc = run_chain(prop, _log_p, base_state(), _feat, N, seed=2)
    assert acc > 0.1
    assert_moments(samples, *truth)
    wrong, _ = run_chain(DropRatio(prop), _log_p, base_state(), _feat, N // 2, seed=2)
    assert moment_errors(wrong[:, :3], truth[0][:3], truth[1][:3]).max() > 0.15


def _gain_light_log_p(p):
    """Log-normal gains (log sd 0.2) x Gaussian light around 1 (sd 0.3), two coefficients per channel."""
    g = np.log(np.asarray(p.color_transform.gain))
    L = np.asarray(p.environment_map.coefficients)
    return float(-0.5 * np.sum((g / 0.2) ** 2) - np.sum(g) - 0.5 * np.sum(((L - 1.0) / 0.3) ** 2))


def _gain_light_feat(p):
    return [*np.log(p.color_transform.gain), *np.asarray(p.environment_map.coefficients)[0]]


def test_gain_light_exchange_keeps_the_image_and_is_its_own_reverse():
    from albedo_model.params import SHLight
    from proposals.color_transform import GainLightExchange

    p = base_state()._replace(environment_map=SHLight(np.full((9, 3), 0.7)))
    move = GainLightExchange(0.1)(np.random.default_rng(0), ProposalState(p))
    q = move.params
    # gain x light per channel is unchanged
    assert np.allclose(np.asarray(q.color_transform.gain)[None, :] *
                       np.asarray(q.environment_map.coefficients), 0.7)
    assert move.touched == Block.COLOR_TRANSFORM | Block.LIGHT
    eps = np.log(np.asarray(q.color_transform.gain))
    assert np.isclose(move.log_q_ratio, (1 - 9) * eps.sum())


def test_gain_light_chain_samples_the_priors_and_its_negative_control_does_not():
    from albedo_model.params import SHLight
    from proposals.color_transform import GainLightExchange
    from proposals.light import SHIntensity, SHPerturbation

    start = base_state()._replace(environment_map=SHLight(np.ones((2, 3))))
    prop = mixture((1.0, GainLightExchange(0.2)), (1.0, ColorTransformWalk(0.2, 0.0, 0.0)),
                   (1.0, SHIntensity(0.2)), (1.0, SHPerturbation(0.2, fix_energy=False)))
    mean = [0.0] * 3 + [1.0] * 3  # log g ~ N(0, 0.2): the density of g is phi(log g) / g
    std = [0.2] * 3 + [0.3] * 3
    samples, acc = run_chain(prop, _gain_light_log_p, start, _gain_light_feat, 3 * N, seed=4)
    assert acc > 0.2
    assert_moments(samples, mean, std)
    wrong, _ = run_chain(mixture((3.0, DropRatio(GainLightExchange(0.2))),
                                 (1.0, ColorTransformWalk(0.2, 0.0, 0.0)),
                                 (1.0, SHIntensity(0.2)),
                                 (1.0, SHPerturbation(0.2, fix_energy=False))),
                         _gain_light_log_p, start, _gain_light_feat, N, seed=4)
    assert moment_errors(wrong, mean, std).max() > 0.15
