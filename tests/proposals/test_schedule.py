"""Default schedules: honest ``touches`` for every proposal, the reference's weights, seeds."""

from __future__ import annotations

import numpy as np
import pytest
from mh_chain import changed_blocks, random_state

from albedo_model.params import Block
from proposals.base import Mixture, ProposalState, leaves
from proposals.pose import ImageCentered
from proposals.schedule import (
    CENTERING_LANDMARKS,
    default_image_proposal,
    landmark_stage_proposal,
)

_BASE_POINTS = {name: np.array([35.0 * (-1) ** i, 30.0 - 60.0 * (i // 2), 80.0])
                for i, name in enumerate(CENTERING_LANDMARKS)}


def landmark_point(name, params):
    return _BASE_POINTS[name] + 3.0 * np.asarray(params.momo.shape[:3])


def solver_data(params):
    rng = np.random.default_rng(0)
    n = rng.normal(size=(50, 3))
    return n, rng.uniform(0.2, 0.8, (50, 3)), rng.uniform(0.1, 0.6, (50, 3))


def _all_leaves(proposal):
    """Leaves of the schedule, plus each inner leaf of the first image-centred wrapper alone
    (the wrappers differ only in their anchor)."""
    out, expanded = [], False
    for _, leaf in leaves(proposal):
        out.append(leaf)
        if isinstance(leaf, ImageCentered) and isinstance(leaf.inner, Mixture) and not expanded:
            out += [ImageCentered(inner, leaf.anchor, label=leaf.label)
                    for _, inner in leaves(leaf.inner)]
            expanded = True
    return out


def _snapshot(p):
    return (p.momo.shape.copy(), p.momo.albedo.copy(), p.momo.expression.copy(),
            p.environment_map.coefficients.copy())


def test_every_proposal_changes_only_its_declared_blocks():
    """200 moves of every leaf of both schedules from random states (leaves shared by the
    two schedules, such as the pose moves, are run once)."""
    rng = np.random.default_rng(0)
    states = [random_state(rng) for _ in range(20)]
    image = default_image_proposal(landmark_point, solver_data=solver_data)
    stage = landmark_stage_proposal(landmark_point, shape_weight=1.0)
    unique = {leaf.name: leaf for leaf in _all_leaves(stage) + _all_leaves(image)}
    # schedule leaves (with the gain-light exchange) + the inner leaves of one centred wrapper
    assert len(unique) == 31 + 15
    for leaf in unique.values():
        seen = Block.NONE
        for i in range(200):
            p = states[i % len(states)]
            before = _snapshot(p)
            move = leaf(rng, ProposalState(p))
            changed = changed_blocks(p, move.params)
            assert changed & ~move.touched == Block.NONE, (leaf.name, changed, move.touched)
            assert move.touched & ~leaf.touches == Block.NONE, (leaf.name, move.touched)
            assert np.isfinite(move.log_q_ratio), leaf.name
            # the input state is never mutated
            assert all(np.array_equal(x, y) for x, y in zip(before, _snapshot(p))), leaf.name
            seen |= changed
        assert seen == leaf.touches, (leaf.name, seen, leaf.touches)  # and it does move them


def test_distance_and_centred_moves_declare_camera():
    prop = default_image_proposal(landmark_point)
    by_name = {leaf.name: leaf for leaf in _all_leaves(prop)}
    assert by_name["distance-500@right.eye.corner_outer"].touches == Block.POSE | Block.CAMERA
    assert by_name["yaw-0.75@right.eye.corner_outer"].touches == Block.POSE | Block.CAMERA
    assert by_name["pose-moving@left.lips.corner"].touches == Block.POSE | Block.CAMERA
    assert by_name["translation-300"].touches == Block.POSE
    assert prop.touches == Block.ALL & ~Block.DIRECTIONAL  # no directional-light walks
    assert landmark_stage_proposal(landmark_point).touches == Block.POSE | Block.CAMERA


def _probabilities(proposal):
    out = {}
    for w, leaf in leaves(proposal):
        if isinstance(leaf, ImageCentered):
            for w_in, inner in leaves(leaf.inner):
                key = f"{inner.name}@{leaf.label}"
                out[key] = out.get(key, 0.0) + w * w_in
        else:
            out[leaf.name] = out.get(leaf.name, 0.0) + w
    return out


def test_reference_scales_and_weights():
    probs = _probabilities(default_image_proposal(landmark_point, solver_data=solver_data,
                                                  specular_weight=0.0, expression_weight=0.5))
    assert sum(probs.values()) == pytest.approx(1.0)
    pose, colour, momo, light = 1 / 7, 1 / 7, 3 / 7, 2 / 7
    centred = pose / 4.2  # each of the four landmarks
    expected = {
        "yaw-0.75@right.eye.corner_outer": centred / 3 * 0.5 * 0.1,
        "pitch-0.1@left.eye.corner_outer": centred / 3 * 0.3 * 0.4,
        "roll-0.01@right.lips.corner": centred / 3 * 0.2 * 0.5,
        "distance-50@left.lips.corner": centred / 3 * 0.6,
        "focal-0.15@left.lips.corner": centred / 3 * 0.2,
        "translation-10": pose * 0.2 / 4.2 * 0.6,
        "shape-0.2": momo / 4 * 0.1, "albedo-0.1": momo / 4 * 0.5,
        "expression-0.025": momo / 2 * 0.2, "shape-caricature-0.2": momo / 4 * 0.2,
        # the reference's colour walks keep 70 %; 30 % are gain-light exchanges (ours)
        "color-transform-0.01": colour * 0.2 * 0.7, "color-transform-0.001": colour * 0.6 * 0.7,
        "color-transform-0.0005": colour * 0.2 * 0.7, "gain-light-0.02": colour * 0.3,
        "sh-spatial-0.05": light / 6, "sh-bands-0.1": light / 6, "sh-intensity-0.05": light / 6,
        "sh-perturb-fixed-0.001": light / 6, "sh-colour-0.01": light / 6,
        "sh-solver": light / 6,
    }
    for name, prob in expected.items():
        assert probs[name] == pytest.approx(prob, rel=1e-12), name
    no_solver = _probabilities(default_image_proposal(landmark_point, specular_weight=0.0))
    assert "sh-solver" not in no_solver
    assert no_solver["sh-bands-0.1"] == pytest.approx(light / 5)
    with_spec = _probabilities(default_image_proposal(landmark_point, specular_weight=0.1))
    spec = sum(v for k, v in with_spec.items() if k.startswith("specular-exponent"))
    assert spec == pytest.approx(0.1 / 7.1)


def test_same_seed_same_moves():
    prop = default_image_proposal(landmark_point, solver_data=solver_data)

    def run(seed):
        rng, p, out = np.random.default_rng(seed), random_state(np.random.default_rng(5)), []
        for _ in range(300):
            move = prop(rng, ProposalState(p))
            out.append(move)
            p = move.params  # accept everything: later moves depend on earlier ones
        return out

    a, b, c = run(11), run(11), run(12)
    for m1, m2 in zip(a, b):
        assert m1.name == m2.name and m1.log_q_ratio == m2.log_q_ratio
        assert m1.touched == m2.touched and changed_blocks(m1.params, m2.params) == Block.NONE
    assert [m.name for m in a] != [m.name for m in c]
