"""Face regions from landmarks: present, disjoint, around their landmarks, frame-free, partial."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from albedo_model.io.model_files import load_model
from albedo_model.regions import REGION_NAMES, face_frame, face_regions, region_masks


@pytest.fixture(scope="module")
def models(default_model_file):
    from mcmcfit.jobs.model_spec import resolve_model

    return {"default": load_model(default_model_file),
            "default-face": load_model(resolve_model("default-face", progress=False))}


def _points(model):
    mean = model.shape_instance()
    return mean, {n: mean[i] for n, i in model.landmark_vertices.items()}


@pytest.mark.parametrize("name", ["default", "default-face"])
def test_every_region_is_there_disjoint_and_around_its_landmarks(models, name):
    model = models[name]
    regions = face_regions(model)
    assert tuple(regions) == REGION_NAMES
    stack = np.stack(list(regions.values()))
    assert stack.shape == (len(REGION_NAMES), model.n_vertices)
    assert np.all(stack.sum(axis=1) >= 50)  # each region holds a patch, not a few vertices
    assert np.all(stack.sum(axis=0) <= 1)  # disjoint
    lv = model.landmark_vertices
    assert regions["nose"][lv["center.nose.tip"]]
    assert regions["eyes"][lv["left.eye.pupil.center"]] and regions["eyes"][lv["right.eye.pupil.center"]]
    assert regions["lips"][lv["center.lips.lower.outer"]]
    assert regions["chin"][lv["center.chin.tip"]]
    # the mirror-symmetric model: cheeks of one size, on their own side of the midline
    v = model.shape_instance()
    assert abs(regions["left_cheek"].sum() - regions["right_cheek"].sum()) <= 0.05 * regions[
        "left_cheek"].sum()
    assert np.all(v[regions["left_cheek"], 0] > 0) and np.all(v[regions["right_cheek"], 0] < 0)
    assert v[regions["forehead"], 1].min() > v[lv["left.eye.top"], 1]
    assert v[regions["chin"], 1].max() < v[lv["center.lips.lower.outer"], 1]


def test_regions_do_not_depend_on_the_model_frame(models):
    """A rotated, scaled (cm instead of mm) and shifted copy of the model has the same regions."""
    mean, points = _points(models["default-face"])
    ref = region_masks(mean, points)
    rot = Rotation.from_euler("xyz", [30, -50, 120], degrees=True).as_matrix()

    def move(p):
        return 0.1 * p @ rot.T + np.array([5.0, -3.0, 40.0])

    got = region_masks(move(mean), {k: move(p) for k, p in points.items()})
    assert list(got) == list(ref)
    for k in ref:  # landmark vertices lie on some boundaries: rounding may flip those few
        assert np.sum(got[k] != ref[k]) <= max(2, 0.01 * ref[k].sum()), k
    frame = face_frame(points, mean)
    np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-12)
    assert frame[0] @ [1, 0, 0] > 0.99 and frame[2] @ [0, 0, 1] > 0.95  # +x left, looks along +z


def test_missing_landmarks_omit_their_regions_only(models):
    mean, points = _points(models["default"])
    full = region_masks(mean, points)
    no_hairline = {k: p for k, p in points.items() if k != "center.front.trichion"}
    got = region_masks(mean, no_hairline)
    assert "forehead" not in got and set(got) == set(full) - {"forehead"}
    for k in got:  # the trichion also tilts the frame's up axis a little
        assert np.sum(got[k] != full[k]) <= 0.1 * full[k].sum(), k
    no_wings = {k: p for k, p in points.items() if ".nose.wing." not in k}
    got = region_masks(mean, no_wings)
    assert not {"nose", "left_cheek", "right_cheek"} & set(got)
    assert {"eyes", "lips", "chin", "forehead"} <= set(got)
    assert np.all(np.stack(list(got.values())).sum(axis=0) <= 1)
    left_only = {k: p for k, p in points.items() if not k.startswith("right.eye.")}
    eyes = region_masks(mean, left_only)["eyes"]
    assert eyes.sum() == pytest.approx(full["eyes"].sum() / 2, rel=0.1)
    assert np.all(mean[eyes, 0] > 0)
    # no lips nor chin: no frame, no regions (nothing is guessed)
    upper_only = {k: p for k, p in points.items() if ".lips." not in k and ".chin." not in k}
    assert region_masks(mean, upper_only) == {}
    assert region_masks(mean, {}) == {}
