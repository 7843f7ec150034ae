"""Coefficient random walks and caricature scaling: index sets, stationarity, Jacobian."""

from __future__ import annotations

import numpy as np
import pytest
from mh_chain import DropRatio, assert_moments, base_state, moment_errors, run_chain

from albedo_model.errors import InputError
from albedo_model.params import Block, MoMoCoefficients
from proposals.base import mixture
from proposals.coefficients import Caricature, CoefficientWalk
from proposals.base import ProposalState

N = 12_000


def _state(shape=(), albedo=(), expression=()):
    momo = MoMoCoefficients(np.asarray(shape, float), np.asarray(albedo, float),
                            np.asarray(expression, float))
    return base_state()._replace(momo=momo)


@pytest.mark.parametrize("block,field", [(Block.SHAPE, "shape"), (Block.ALBEDO, "albedo"),
                                         (Block.EXPRESSION, "expression")])
def test_walk_moves_whole_vector_slice_or_one_chunk(block, field):
    rng = np.random.default_rng(0)
    p = _state(np.zeros(23), np.zeros(23), np.zeros(23))
    whole = CoefficientWalk(block, 0.1)(rng, ProposalState(p))
    assert np.all(getattr(whole.params.momo, field) != 0)
    part = CoefficientWalk(block, 0.1, index=slice(4, 9))(rng, ProposalState(p))
    changed = np.flatnonzero(getattr(part.params.momo, field))
    np.testing.assert_array_equal(changed, np.arange(4, 9))
    seen = set()
    for _ in range(200):
        move = CoefficientWalk(block, 0.1, block_size=10)(rng, ProposalState(p))
        changed = np.flatnonzero(getattr(move.params.momo, field))
        assert move.log_q_ratio == 0.0 and move.touched == block
        chunk = (int(changed[0]), int(changed[-1]) + 1)
        assert chunk in {(0, 10), (10, 20), (20, 23)}
        np.testing.assert_array_equal(changed, np.arange(*chunk))
        seen.add(chunk)
    assert len(seen) == 3
    assert not np.any(getattr(p.momo, field))  # input untouched


def test_walk_on_an_empty_vector_is_the_identity():
    p = _state(np.zeros(3))
    move = CoefficientWalk(Block.EXPRESSION, 0.1, block_size=10)(np.random.default_rng(0), ProposalState(p))
    assert move.params is p and move.touched == Block.NONE and move.log_q_ratio == 0.0


def test_walk_chain_matches_gaussian():
    m, s = np.array([0.5, -1.0, 0.0, 2.0, 0.3, -0.2]), np.array([1.0, 0.5, 1.2, 1.0, 0.6, 0.8])
    prop = CoefficientWalk(Block.SHAPE, 2.0, block_size=1)
    log_p = lambda p: -0.5 * np.sum(((p.momo.shape - m) / s) ** 2)  # noqa: E731
    samples, _ = run_chain(prop, log_p, _state(np.zeros(6)), lambda p: p.momo.shape, N, seed=1)
    assert_moments(samples, m, s)


def test_caricature_scales_and_has_ratio_k_log_s():
    x = np.random.default_rng(2).normal(size=7)
    move = Caricature(Block.ALBEDO, 0.2)(np.random.default_rng(3), ProposalState(_state(albedo=x)))
    s = move.params.momo.albedo / x
    np.testing.assert_allclose(s, s[0], rtol=1e-12)
    assert move.log_q_ratio == pytest.approx(7 * np.log(s[0]), rel=1e-12)
    zero = Caricature(Block.ALBEDO, 0.2)(np.random.default_rng(3), ProposalState(_state(albedo=np.zeros(4))))
    assert zero.touched == Block.NONE


def test_caricature_alone_samples_the_chi_radius():
    """Along a ray, N(0, I_k) gives r^2 ~ chi^2_k: mean k, sd sqrt(2k)."""
    k = 8
    x0 = np.random.default_rng(4).normal(size=k)
    prop = mixture((0.5, Caricature(Block.SHAPE, 0.3)), (0.5, Caricature(Block.SHAPE, 0.1)))
    log_p = lambda p: -0.5 * float(p.momo.shape @ p.momo.shape)  # noqa: E731
    feat = lambda p: [float(p.momo.shape @ p.momo.shape)]  # noqa: E731
    samples, _ = run_chain(prop, log_p, _state(x0), feat, N, seed=5)
    assert_moments(samples, k, np.sqrt(2 * k))
    wrong, _ = run_chain(DropRatio(prop), log_p, _state(x0), feat, N // 2, seed=5)
    assert moment_errors(wrong, k, np.sqrt(2 * k)).max() > 0.15


def test_caricature_and_walk_jointly_sample_a_shifted_gaussian():
    m, s = np.array([1.0, -0.5, 2.0, 0.0]), np.array([0.5, 1.0, 0.7, 1.2])
    prop = mixture((1.0, Caricature(Block.EXPRESSION, 0.3)),
                   (1.0, CoefficientWalk(Block.EXPRESSION, 2.0, block_size=1)))
    log_p = lambda p: -0.5 * np.sum(((p.momo.expression - m) / s) ** 2)  # noqa: E731
    samples, _ = run_chain(prop, log_p, _state(expression=np.ones(4)),
                           lambda p: p.momo.expression, 2 * N, seed=6)  # x_i walks 1/8 of steps
    assert_moments(samples, m, s)


def test_bad_arguments_raise():
    with pytest.raises(InputError):
        CoefficientWalk(Block.POSE, 0.1)
    with pytest.raises(InputError):
        CoefficientWalk(Block.SHAPE, -1.0)
    with pytest.raises(InputError):
        CoefficientWalk(Block.SHAPE, 0.1, index=slice(0, 2), block_size=2)
    with pytest.raises(InputError):
        Caricature(Block.SHAPE, 0.0)
