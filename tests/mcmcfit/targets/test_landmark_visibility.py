"""Landmark visibility: a shallow shell in front of a landmark does not hide it, a head does."""

from __future__ import annotations

import math

import numpy as np
from face_factory import scene, small_face_model

from mcmcfit.targets.landmarks import VISIBILITY_SHELL, LandmarkGeometry


def test_the_shell_is_about_a_centimetre_on_a_head():
    geometry = LandmarkGeometry(small_face_model(), threads=1)
    depth = VISIBILITY_SHELL * geometry._caster.scale
    assert 5.0 < depth < 15.0  # mm: creases are shallower, a head is deeper


def test_frontal_landmarks_are_visible_and_the_far_side_hidden_in_profile():
    model = small_face_model()
    geometry = LandmarkGeometry(model, threads=1)
    names = [n for n in geometry.names if n.startswith(("left.eye", "right.eye"))]
    assert names
    front = geometry.visible(names, scene(128, 128))
    assert front.all()
    # turned by 80 deg, the eye corners of one side lie behind ~100 mm of head
    turned = geometry.visible(names, scene(128, 128, yaw=math.radians(80.0)))
    hidden = [n for n, v in zip(names, turned) if not v]
    assert hidden and all(n.startswith(hidden[0].split(".")[0]) for n in hidden)
    assert np.any(turned)
