"""The joint fit's column layout: the identity once, every image's own columns, exact round trips."""

from __future__ import annotations

import numpy as np
import pytest
from mh_chain import random_state

from albedo_model.errors import InputError
from mcmcfit.sampling.joint_layout import JointParamLayout
from mcmcfit.sampling.param_vector import ParamLayout
from proposals.joint import JointParameter


@pytest.fixture()
def joint():
    rng = np.random.default_rng(0)
    return JointParameter.share([random_state(rng, n_shape=4, n_albedo=3, n_expression=2)
                                 for _ in range(3)])


def test_round_trip_and_names(joint):
    layout = JointParamLayout.for_params(joint)
    single = ParamLayout.for_params(joint.images[0])
    own = single.size - 4 - 3
    assert layout.size == 4 + 3 + 3 * own == len(layout.names)
    assert layout.names[:7] == ("shape.0", "shape.1", "shape.2", "shape.3", "albedo.0",
                                "albedo.1", "albedo.2")
    assert layout.names[7] == "image0.pose.yaw" and "image2.expression.1" in layout.names
    v = layout.to_vector(joint)
    back = layout.from_vector(v, joint)
    np.testing.assert_array_equal(layout.to_vector(back), v)
    for k, p in enumerate(joint.images):
        np.testing.assert_array_equal(layout.image_vectors(v, k), single.to_vector(p))
        assert back.images[k].pose == p.pose
    assert back.images[0].momo.albedo is back.images[2].momo.albedo
    np.testing.assert_array_equal(v[layout.slice("albedo")], joint.images[0].momo.albedo)
    assert layout.index("image1.light.0.g") == layout.names.index("image1.light.0.g")


def test_bad_use_is_refused(joint):
    layout = JointParamLayout.for_params(joint)
    with pytest.raises(InputError, match="one 'light' per image"):
        layout.slice("light")
    with pytest.raises(InputError, match="2 images, the layout 3"):
        layout.to_vector(JointParameter(joint.images[:2]))
    with pytest.raises(InputError, match="values, layout needs"):
        layout.from_vector(np.zeros(3), joint)
    other = joint.images[1]._replace(momo=joint.images[1].momo._replace(expression=np.zeros(5)))
    with pytest.raises(InputError, match="same block sizes"):
        JointParamLayout.for_params(JointParameter((joint.images[0], other)))
