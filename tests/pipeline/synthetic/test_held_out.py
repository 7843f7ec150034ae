"""Held-out subjects are excluded from the model; skin detail raises the projection floor."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.synthetic.held_out import build_held_out_population, held_out_indices
from pipeline.synthetic.skin_detail import (
    DETAIL_KINDS,
    SkinDetail,
    add_skin_detail,
    projection_floor,
)


@pytest.fixture(scope="module")
def population(default_model_file):
    return build_held_out_population(4, 2, seed=5)


def test_held_out_subjects_are_not_in_the_model(population):
    assert held_out_indices(4, 2) == [4, 5]
    assert [s.index for s in population.training] == [0, 1, 2, 3]
    assert [h.index for h in population.held_out] == [4, 5]
    provenance = json.loads(population.model.metadata["provenance"])
    assert provenance["held_out_subjects"] == [4, 5] and provenance["subjects"] == 4
    part = population.model.diffuse
    # every training subject is in the model's span (4 subjects + mirrors: rank 7) ...
    for s in population.training:
        assert projection_floor(part, s.diffuse) < 1e-9
    # ... a held-out one is not, even without detail
    for h in population.held_out:
        assert projection_floor(part, h.smooth_diffuse) > 1e-5


def test_skin_detail_raises_the_projection_floor(population):
    part = population.model.diffuse
    for h in population.held_out:
        assert h.detail == list(DETAIL_KINDS)
        # a 4-subject model misses much of a smooth face already (with the 60-subject
        # default model the detail raises the floor 3-5x: 1.6e-4 -> 8.6e-4 for subject 60)
        assert projection_floor(part, h.diffuse) > projection_floor(part, h.smooth_diffuse) + 5e-5


def test_each_kind_of_detail_is_switchable(population):
    head = population.head
    s = population.training[0]
    smooth_d, _ = add_skin_detail(s.diffuse, s.specular, head, 1, SkinDetail.none())
    np.testing.assert_array_equal(smooth_d, s.diffuse)
    floor0 = projection_floor(population.model.diffuse, s.diffuse)
    for kind in DETAIL_KINDS:
        only = SkinDetail(**{k: k == kind for k in DETAIL_KINDS})
        assert only.enabled() == [kind]
        d, sp = add_skin_detail(s.diffuse, s.specular, head, 1, only)
        assert np.all((d >= 0) & (d <= 1)) and np.all((sp >= 0) & (sp <= 1))
        changed = np.any(np.abs(d - s.diffuse) > 1e-3, axis=1)
        assert changed.any(), kind
        assert projection_floor(population.model.diffuse, d) > floor0 + 1e-7, kind
    # same seed, same detail; another seed, other detail
    a, _ = add_skin_detail(s.diffuse, s.specular, head, 1)
    b, _ = add_skin_detail(s.diffuse, s.specular, head, 1)
    c, _ = add_skin_detail(s.diffuse, s.specular, head, 2)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_projection_floor_of_srgb_part_decodes(population):
    from albedo_model.io.colour_space import encode_texture
    from albedo_model.pca import pca_from_data

    maps = np.stack([s.diffuse for s in population.training])
    part = pca_from_data(encode_texture(maps).reshape(len(maps), -1))
    assert projection_floor(part, population.training[1].diffuse, colour="srgb") < 1e-12
    assert projection_floor(part, population.training[1].diffuse) > 1e-3  # read as linear: wrong
