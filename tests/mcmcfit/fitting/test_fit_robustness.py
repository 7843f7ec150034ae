"""fit() input checks: all-black image, too few known landmarks (unknown ones warned, ignored)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.errors import InputError
from mcmcfit.fitting.fit import fit
from mcmcfit.fitting.config import FitConfig

TINY = FitConfig(steps=5, landmark_steps=5, chains=1)


@pytest.fixture(scope="module")
def small_model():
    return small_face_model()


@pytest.fixture(scope="module")
def target(small_model):
    return synthetic_target(small_model, scene(48, 48, yaw=0.2))


def test_all_black_image_is_an_input_error(small_model, target):
    _, clicks = target
    with pytest.raises(InputError, match="black"):
        fit(np.zeros((48, 48, 3)), clicks, small_model, config=TINY)


def test_non_finite_image_is_an_input_error(small_model, target):
    image, clicks = target
    bad = image.copy()
    bad[3, 4, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        fit(bad, clicks, small_model, config=TINY)


def test_fewer_than_three_known_landmarks_is_an_input_error(small_model, target):
    image, clicks = target
    two = dict(list(clicks.items())[:2])
    two["no.such.point"] = (10.0, 10.0)
    with pytest.raises(InputError, match="at least 3"):
        fit(image, two, small_model, config=TINY)
    with pytest.raises(InputError, match="none of the"):
        fit(image, {"no.such.point": (1.0, 2.0)}, small_model, config=TINY)


def test_unknown_landmarks_are_warned_about_and_ignored(small_model, target):
    image, clicks = target
    extra = dict(clicks, **{"no.such.point": (10.0, 10.0), "nor.this": (20.0, 5.0)})
    with pytest.warns(UserWarning, match="no.such.point") as rec:
        res = fit(image, extra, small_model, config=TINY, seed=3)
    assert "nor.this" in str(rec[0].message)
    assert set(res.landmarks_unknown) == {"no.such.point", "nor.this"}
    assert set(res.landmarks_used) == set(clicks)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        same = fit(image, clicks, small_model, config=TINY, seed=3)
    # the unknown names change nothing in the chain
    assert np.array_equal(same.chains[0].stage2.samples, res.chains[0].stage2.samples)
