"""Move / Proposal / mixture: weights, frequencies, union of blocks, pass-through of moves."""

from __future__ import annotations

import numpy as np
import pytest
from mh_chain import base_state

from albedo_model.errors import InputError
from albedo_model.params import Block
from proposals.base import Move, Proposal, leaves, mixture
from proposals.pose import FocalScaling, Rotation
from proposals.base import ProposalState


class Tagged:
    """A proposal that changes nothing and tags its move with a name and a ratio."""

    def __init__(self, name, touches=Block.NONE, ratio=0.0):
        self.name, self.touches, self.ratio = name, touches, ratio

    def __call__(self, rng, params):
        return Move(params, self.ratio, Block.NONE, self.name)


def test_weights_are_normalised_and_zero_weights_dropped():
    mix = mixture((2.0, Tagged("a", Block.POSE)), (0.0, Tagged("b", Block.LIGHT)),
                  (6.0, Tagged("c", Block.SHAPE)), name="m")
    np.testing.assert_allclose(mix.weights, [0.25, 0.75])
    assert [c.name for c in mix.components] == ["a", "c"]
    assert mix.touches == Block.POSE | Block.SHAPE and mix.name == "m"
    assert isinstance(mix, Proposal) and isinstance(Rotation("yaw", 0.1), Proposal)


@pytest.mark.parametrize("bad", [(), ((-1.0, Tagged("a")),), ((np.nan, Tagged("a")),),
                                 ((0.0, Tagged("a")),), (Tagged("a"),)])
def test_bad_weights_raise(bad):
    with pytest.raises(InputError):
        mixture(*bad)


def test_component_frequencies_match_weights():
    weights = np.array([1.0, 2.0, 5.0, 0.5])
    mix = mixture(*((w, Tagged(str(i))) for i, w in enumerate(weights)))
    rng, n = np.random.default_rng(0), 40_000
    counts = np.zeros(4)
    p = base_state()
    for _ in range(n):
        counts[int(mix(rng, ProposalState(p)).name)] += 1
    prob = weights / weights.sum()
    se = np.sqrt(prob * (1 - prob) / n)
    assert np.all(np.abs(counts / n - prob) < 4.5 * se)


def test_nested_mixture_leaf_probabilities_and_frequencies():
    inner = mixture((1.0, Tagged("x")), (3.0, Tagged("y")))
    outer = mixture((1.0, inner), (1.0, Tagged("z")))
    probs = {leaf.name: w for w, leaf in leaves(outer)}
    assert probs == pytest.approx({"x": 0.125, "y": 0.375, "z": 0.5})
    rng, n = np.random.default_rng(1), 20_000
    names = [outer(rng, ProposalState(base_state())).name for _ in range(n)]
    for k, prob in probs.items():
        assert abs(names.count(k) / n - prob) < 4.5 * np.sqrt(prob * (1 - prob) / n)


def test_the_component_move_is_returned_unchanged():
    mix = mixture((1.0, Tagged("a", ratio=0.25)), (1.0, Tagged("b", ratio=-1.5)))
    for seed in range(10):
        move = mix(np.random.default_rng(seed), ProposalState(base_state()))
        assert move.log_q_ratio == {"a": 0.25, "b": -1.5}[move.name]


def test_multiscale_log_normal_mixture_ratio_is_every_components_ratio():
    """Same family, different scales: each component's ratio is log f' - log f, so the
    marginal mixture ratio log(sum w q_i(f|f')) - log(sum w q_i(f'|f)) equals it."""
    sig, w = np.array([0.15, 0.05, 0.01]), np.array([0.2, 0.6, 0.2])
    mix = mixture(*((wi, FocalScaling(s)) for wi, s in zip(w, sig)))
    p = base_state()
    f = p.camera.focal_length
    for seed in range(20):
        move = mix(np.random.default_rng(seed), ProposalState(p))
        f2 = move.params.camera.focal_length

        def q(a, b):  # density of b given a, sum over components (log-normal)
            z = np.log(b / a)
            return np.sum(w * np.exp(-0.5 * (z / sig) ** 2) / (sig * np.sqrt(2 * np.pi) * b))

        assert move.log_q_ratio == pytest.approx(np.log(q(f2, f)) - np.log(q(f, f2)), abs=1e-9)
