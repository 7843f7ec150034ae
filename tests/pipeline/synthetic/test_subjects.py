"""Synthetic subjects: determinism, Fitzpatrick balance, colour range, regional structure."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from pipeline.synthetic.subjects import make_subjects, region_weights

LIGHT_END = np.array([0.50, 0.32, 0.27])
DARK_END = np.array([0.06, 0.03, 0.02])


@pytest.fixture(scope="module")
def population(stand_in_head):
    return make_subjects(stand_in_head, 12, seed=3)


def _plain_skin(head):
    r = head.regions
    other = r["eyeballs"] | r["lips"] | r["brows"] | r["beard"] | r["ears"]
    w = region_weights(head)
    near = sum(w[k] for k in ("eyeballs", "lips", "brows", "beard", "ears")) > 0.01
    return r["skin"] & ~other & ~near


def _lum(rgb):
    return rgb @ np.array([0.2126, 0.7152, 0.0722])


def test_same_seed_same_subjects_and_prefix_stable(stand_in_head, population):
    again = make_subjects(stand_in_head, 12, seed=3)
    for a, b in zip(population, again):
        assert np.array_equal(a.diffuse, b.diffuse) and np.array_equal(a.specular, b.specular)
        assert (a.fitzpatrick, a.tone, a.beard) == (b.fitzpatrick, b.tone, b.beard)
    short = make_subjects(stand_in_head, 3, seed=3)
    assert np.array_equal(short[2].diffuse, population[2].diffuse)
    other = make_subjects(stand_in_head, 1, seed=4)[0]
    assert not np.allclose(other.diffuse, population[0].diffuse)


def test_fitzpatrick_types_balanced(population):
    types = [s.fitzpatrick for s in population]
    assert sorted(types) == sorted(list(range(1, 7)) * 2)


def test_albedo_within_stated_linear_srgb_range(stand_in_head, population):
    skin = _plain_skin(stand_in_head)
    assert skin.sum() > 200
    for s in population:
        assert s.diffuse.shape == s.specular.shape == (len(stand_in_head.vertices), 3)
        assert s.diffuse.min() >= 0 and s.diffuse.max() <= 1
        assert s.specular.min() >= 0 and s.specular.max() <= 1
        median = np.median(s.diffuse[skin], axis=0)
        assert np.all(median <= LIGHT_END * 1.05) and np.all(median >= DARK_END * 0.8), median
        lo, hi = np.percentile(s.diffuse[skin], [2, 98], axis=0)
        assert np.all(hi <= LIGHT_END * 1.2) and np.all(lo >= DARK_END * 0.5), (lo, hi)
    by_type = {s.fitzpatrick: np.median(s.diffuse[skin], axis=0) for s in population}
    assert by_type[1][0] > 0.38 and by_type[6][0] < 0.12
    assert np.all(np.diff([_lum(by_type[k]) for k in range(1, 7)]) < 0)


def test_regional_structure(stand_in_head, population):
    r = stand_in_head.regions
    skin = _plain_skin(stand_in_head)
    names = ("lips", "cheeks", "forehead", "brows", "beard", "nose")
    core = {k: r[k] & ~r["eyeballs"] for k in names}
    cheeks_redder = []
    for s in population:
        d, sp = s.diffuse, s.specular[:, 1]
        redness = {k: np.mean(d[m, 0] / d[m, 1]) for k, m in core.items()}
        assert redness["lips"] > redness["cheeks"]
        cheeks_redder.append(redness["cheeks"] > redness["forehead"])
        assert _lum(d[core["brows"]]).mean() < _lum(d[core["forehead"]]).mean()
        assert sp[core["forehead"]].mean() > sp[core["beard"]].mean()
        assert sp[core["nose"]].mean() > sp[core["cheeks"]].mean()
        assert sp[core["forehead"]].mean() > sp[skin].mean() > sp[core["brows"]].mean()
        if s.beard > 0.5:
            assert _lum(d[core["beard"] & ~r["lips"]]).mean() < _lum(d[core["cheeks"]]).mean()
    assert np.mean(cheeks_redder) >= 0.75
    bearded = [s for s in population if s.beard > 0]
    clean = [s for s in population if s.beard == 0]
    assert bearded and clean


def test_specular_is_near_grey_and_eyes_have_sclera(stand_in_head, population):
    v = stand_in_head.vertices
    eyes = stand_in_head.regions["eyeballs"]
    pupils = [stand_in_head.landmarks[f"{s}.eye.pupil.center"] for s in ("left", "right")]
    far = np.min([np.linalg.norm(v - v[i], axis=1) for i in pupils], axis=0) > 8.0
    sclera = eyes & far
    for s in population:
        spread = s.specular.max(axis=1) / s.specular.min(axis=1)
        assert spread.max() < 1.1
        assert np.all((s.diffuse[sclera] > 0.5) & (s.diffuse[sclera] < 0.75))
        assert np.all(s.diffuse[pupils] < 0.05)


def test_symmetric_and_asymmetric_parts(stand_in_head, population):
    sym = stand_in_head.symmetry
    for s in population:
        x = np.log(s.melanin)
        corr = np.corrcoef(x, x[sym])[0, 1]
        assert 0.8 < corr < 0.9999


def test_bad_template_symmetry_raises(stand_in_head):
    import dataclasses

    bad = dataclasses.replace(stand_in_head, symmetry=np.roll(stand_in_head.symmetry, 1))
    with pytest.raises(InputError, match="involution"):
        make_subjects(bad, 1, seed=0)


def test_real_template_if_available():
    template_head = pytest.importorskip("pipeline.synthetic.head.template_head")
    head = template_head.build_template_head()
    missing = {"eyeballs", "lips", "brows", "beard", "forehead", "cheeks"} - set(head.regions)
    if missing:
        pytest.skip(f"template head has no regions {sorted(missing)} yet")
    subjects = make_subjects(head, 2, seed=0)
    assert subjects[0].diffuse.shape == (len(head.vertices), 3)
    lips, forehead = head.regions["lips"], head.regions["forehead"]
    d = subjects[0].diffuse
    assert np.mean(d[lips, 0] / d[lips, 1]) > np.mean(d[forehead, 0] / d[forehead, 1])
