"""``mcmcfit bench joint`` on a small face: one row per number of images, the plain target beside."""

from __future__ import annotations

import pytest
from face_factory import small_face_model

from albedo_model.errors import InputError
from mcmcfit.bench.joint_bench import format_joint_bench, run_joint_bench
from mcmcfit.fitting.config import FitConfig


def test_rows_for_each_number_of_images():
    model = small_face_model()
    result = run_joint_bench(model, images=(1, 2), steps=20, warmup=5, size=64,
                             config=FitConfig(sigma_px=0.02))
    rows = result["rows"]
    assert [r["images"] for r in rows] == [1, 2]
    assert rows[0]["ratio_to_one"] == 1.0
    for r in rows:
        assert r["ms_per_step"] > 0 and 0.0 <= r["acceptance"] <= 1.0
        assert 0.0 < r["shared_fraction"] < 1.0
    assert result["single"]["ms_per_step"] > 0
    text = format_joint_bench(result)
    assert "x one image" in text and "without the joint wrapper" in text


@pytest.mark.parametrize("images", [(), (0, 1), (5,)])
def test_bad_image_counts_are_refused(images):
    with pytest.raises(InputError, match="numbers of images must be in 1..4"):
        run_joint_bench(small_face_model(), images=images)
