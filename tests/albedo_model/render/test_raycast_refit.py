"""Embree ray caster: in-place BVH refit, its self-check and fallbacks, double buffering.

Meshes and poses: raycast_meshes.py.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest

pytest.importorskip("embreex")
pytest.importorskip("trimesh")

from albedo_model import camera as cam  # noqa: E402
from albedo_model.render import embree_refit, raycast  # noqa: E402
from albedo_model.render.scene_slots import SceneSlots  # noqa: E402
from albedo_model.params import ImageSize, Pose, View  # noqa: E402

from raycast_meshes import bumpy_sphere, icosphere, scene  # noqa: E402

pytestmark = pytest.mark.embree


def deformations(v, n, seed=0):
    rng = np.random.default_rng(seed)
    for k in range(n):
        yield v * (1 + 0.1 * np.sin(v / rng.uniform(20, 60, 3) + k)) + rng.normal(0, 10, 3)


def test_refit_equals_fresh_build():
    assert raycast.refit_check() == (True, "refit verified")
    v, f = bumpy_sphere()
    caster = raycast.RayCaster(v, f, update="refit")
    assert caster.refit_supported and caster.update_method == "refit"
    size = ImageSize(96, 96)
    o, d = cam.camera_rays(scene(size), size, Pose(yaw=0.3, pitch=-0.2), View())
    for vk in deformations(v, 4):
        caster.update_vertices(vk)
        got = caster.cast(o, d)
        want = raycast.RayCaster(vk, f, update="rebuild").cast(o, d)
        assert got.mask.mean() > 0.3
        np.testing.assert_array_equal(got.prim_id, want.prim_id)
        np.testing.assert_allclose(got.bary, want.bary, atol=1e-5)
        np.testing.assert_allclose(got.t[got.mask], want.t[want.mask], rtol=1e-6)


def test_refit_failure_falls_back_to_rebuild(monkeypatch, caplog):
    v, f = icosphere()
    size = ImageSize(64, 64)
    o, d = cam.camera_rays(scene(size), size, Pose(), View())

    def broken(*args, **kwargs):
        raise embree_refit.RefitUnavailable("simulated layout change")

    with caplog.at_level(logging.INFO, logger="albedo_model.render.raycast"):
        monkeypatch.setattr(raycast, "prepare_refit", broken)
        caster = raycast.RayCaster(v, f)
    assert not caster.refit_supported and caster.update_method == "rebuild"
    assert "simulated layout change" in caplog.text
    monkeypatch.undo()

    live = raycast.RayCaster(v, f)
    monkeypatch.setattr(embree_refit.RefitHandle, "update", broken)
    for c in (caster, live):
        vk = next(deformations(v, 1))
        c.update_vertices(vk)
        want = raycast.RayCaster(vk, f, update="rebuild").cast(o, d)
        np.testing.assert_array_equal(c.cast(o, d).prim_id, want.prim_id)
    assert live.update_method == "rebuild"


def test_scene_slots_double_buffering():
    v, f = bumpy_sphere()
    size = ImageSize(64, 64)
    o, d = cam.camera_rays(scene(size), size, Pose(yaw=0.5), View())
    slots = SceneSlots(v, f)
    before = slots.current.cast(o, d)
    assert slots.candidate is slots.current and not slots.pending
    v1, v2 = deformations(v, 2, seed=4)
    cand = slots.propose(v1)
    assert slots.candidate is cand and cand is not slots.current and slots.pending
    proposed = cand.cast(o, d)
    assert (proposed.prim_id != before.prim_id).any()
    slots.reject()
    assert slots.candidate is slots.current and not slots.pending
    for x, y in zip(slots.current.cast(o, d), before):
        np.testing.assert_array_equal(x, y)  # a rejected proposal changed nothing
    slots.propose(v2)
    slots.accept()
    want = raycast.RayCaster(v2, f).cast(o, d)
    np.testing.assert_array_equal(slots.current.cast(o, d).prim_id, want.prim_id)
    spare_before = slots._slots[1]
    slots.propose(v1)  # reuses the spare (the old current) by refit
    assert slots.candidate is spare_before
    np.testing.assert_array_equal(slots.candidate.cast(o, d).prim_id, proposed.prim_id)


def _embreex_builder():
    from embreex import mesh_construction, rtcore, rtcore_scene

    device = rtcore.EmbreeDevice()

    def build(v, f):
        scene = rtcore_scene.EmbreeScene(device, robust=False)
        mesh_construction.TriangleMesh(scene, v, f)
        return scene, device

    return build, device


def test_refit_self_check_detects_failures(monkeypatch):
    build, device = _embreex_builder()
    assert embree_refit.verify_refit(build) == (True, "refit verified")

    def boom(v, f):
        raise RuntimeError("no scene")

    assert embree_refit.verify_refit(boom) == (False, "RuntimeError: no scene")
    # a refit that silently does nothing must be caught by the hit comparison
    monkeypatch.setattr(embree_refit.RefitHandle, "update", lambda self, v: None)
    ok, reason = embree_refit.verify_refit(build)
    assert not ok and "differ" in reason


def test_refit_pointer_checks_reject_wrong_objects():
    from embreex import rtcore

    build, _ = _embreex_builder()
    v, f = icosphere()
    scene, device = build(v.astype(np.float32), f.astype(np.int32))
    with pytest.raises(embree_refit.RefitUnavailable, match="layout"):
        embree_refit.prepare_refit(scene, rtcore.EmbreeDevice(), v.astype(np.float32))
    with pytest.raises(embree_refit.RefitUnavailable):
        embree_refit.prepare_refit(scene, device, v[::-1].astype(np.float32))
    handle = embree_refit.prepare_refit(scene, device, v.astype(np.float32))
    assert scene.is_committed == 1 and handle.vertices.shape == (len(v), 4)


def test_failed_process_check_means_rebuild(monkeypatch):
    monkeypatch.setattr(raycast, "refit_check", lambda: (False, "simulated"))
    v, f = icosphere()
    caster = raycast.RayCaster(v, f)
    assert caster.update_method == "rebuild"
    caster.update_vertices(v * 1.5)
    o = np.array([[0, 0, 500]], np.float32)
    d = np.array([[0, 0, -1]], np.float32)
    assert caster.cast(o, d).t[0] == pytest.approx(350.0, abs=0.5)
