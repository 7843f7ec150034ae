"""Capture simulator: rig geometry, shading, polarisation, raw albedo, effect switches."""

import dataclasses

import numpy as np
import pytest

from albedo_model.model import vertex_normals
from albedo_model.render.raycast import RayCaster
from pipeline.synthetic import capture as lightstage_sim
from pipeline.lightstage.colour import camera_colour
from pipeline.synthetic.dome import (
    DOME_RADIUS_MM,
    POSES,
    build_rig,
    camera_in_mesh_frame,
    dome_leds,
    look_at_camera,
    pose_transform,
)
from pipeline.lightstage.dome_shading import LedShading, reference_irradiance, specular_lobe
from pipeline.synthetic.capture import (
    CaptureEffects,
    SimulationSettings,
    exposure_constant,
    misalignment_field,
    simulate_capture,
    subject_raw_albedo,
)
from pipeline.lightstage.polarisation import polarised_pair, separate_polarisation
from pipeline.synthetic.subjects import make_subjects

SMALL = SimulationSettings(resolution=96, extra_resolution=32, boundary_distance_px=3.0)


def test_dome_has_41_leds_on_a_once_subdivided_icosahedron():
    leds = dome_leds()
    assert leds.shape == (41, 3)
    assert np.allclose(np.linalg.norm(leds, axis=1), DOME_RADIUS_MM)
    # neighbours of a once-subdivided icosahedron are arctan(2)/2 apart (31.72 degrees)
    unit = leds / DOME_RADIUS_MM
    cos = np.clip(unit @ unit.T, -1, 1)
    np.fill_diagonal(cos, -1)
    assert np.allclose(np.arccos(cos.max(axis=1)), np.arctan(2.0) / 2.0, atol=1e-9)
    # the missing vertex is the one straight down
    assert unit[:, 1].min() > -0.9 and np.isclose(unit[:, 1].max(), 1.0)


def test_look_at_camera_projects_target_to_centre_and_up_is_up():
    cam = look_at_camera(np.array([0.0, 0.0, 800.0]), np.zeros(3), focal_px=500,
                         image_size=(101, 201))
    uv = cam.project(np.array([[0.0, 0.0, 0.0], [0.0, 10.0, 0.0], [10.0, 0.0, 0.0]]))
    assert np.allclose(uv[0], [100.0, 50.0])
    assert uv[1, 1] < uv[0, 1]          # higher in the world -> smaller row
    assert uv[2, 0] > uv[0, 0]          # +x (subject's left) -> image right


def test_camera_in_mesh_frame_agrees_with_rig_camera():
    rng = np.random.default_rng(0)
    rig = build_rig(resolution=64, extra_resolution=32, distortion=True)
    pose = pose_transform("left", rng)
    pts = rng.normal(size=(20, 3)) * 60
    cam = camera_in_mesh_frame(rig.photometric, pose)
    assert np.allclose(cam.project(pts), rig.photometric.project(pose.apply(pts)))
    assert np.allclose(cam.centre, np.linalg.solve(pose.rotation,
                                                   rig.photometric.centre - pose.translation))


def test_reference_irradiance_is_one_at_the_dome_centre():
    rig = build_rig(resolution=64, extra_resolution=32)
    e_ref = reference_irradiance(rig.leds, np.zeros(3), rig.photometric.centre)
    n = rig.photometric.centre / np.linalg.norm(rig.photometric.centre)
    shading = LedShading(np.zeros((1, 3)), n[None], rig.leds, reference=e_ref)
    assert np.isclose(shading.irradiance()[0], 1.0)
    # brute force: sum of cosines over inverse squares
    d = rig.leds
    cos = np.maximum(0, d @ n / np.linalg.norm(d, axis=1))
    assert np.isclose(e_ref, np.sum(cos / np.sum(d * d, axis=1)))


def test_specular_lobe_matches_a_direct_evaluation():
    rng = np.random.default_rng(1)
    p = rng.normal(size=(500, 3)) * 50
    n = rng.normal(size=(500, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    leds = dome_leds()
    per_led = rng.random((500, 41))
    eye = np.array([0.0, 60.0, 880.0])
    got = specular_lobe(per_led, p, n, leds, eye, 20.0)
    v = eye - p
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    w = leds[None] - p[:, None]
    w /= np.linalg.norm(w, axis=2, keepdims=True)
    h = w + v[:, None]
    h /= np.linalg.norm(h, axis=2, keepdims=True)
    nh = np.clip(np.einsum("plk,pk->pl", h, n), 0, 1)
    ref = np.where(np.einsum("pk,pk->p", n, v) > 0, (per_led * nh**20).sum(1) * 28 / 8, 0.0)
    # float32 arithmetic; worst where an LED lies almost opposite the camera (|w + v| small)
    assert np.allclose(got, ref, rtol=2e-3, atol=1e-6 * ref.max())
    assert np.median(np.abs(got - ref)[ref > 0] / ref[ref > 0]) < 1e-5


def test_self_shadowing_only_where_the_mesh_blocks(stand_in_head):
    v, t = stand_in_head.vertices, stand_in_head.triangles
    leds = dome_leds()
    nrm = vertex_normals(v, t)
    free = LedShading(v, nrm, leds, reference=1.0)
    # a convex head cannot shadow itself
    convex = LedShading(v, nrm, leds, reference=1.0, caster=RayCaster(v, t))
    assert np.allclose(convex.irradiance(), free.irradiance(), rtol=1e-6)
    # a flat disc above the head shadows its top, not what faces downwards
    blocker = v * [3.0, 0.1, 3.0] + [0.0, 250.0, 0.0]
    both_v = np.vstack([v, blocker])
    both_t = np.vstack([t, t + len(v)])
    shadowed = LedShading(v, nrm, leds, reference=1.0, caster=RayCaster(both_v, both_t))
    top = v[:, 1] > 80
    chin = nrm[:, 1] < -0.9
    assert np.all(shadowed.irradiance()[top] < 0.9 * free.irradiance()[top])
    assert np.allclose(shadowed.irradiance()[chin], free.irradiance()[chin], rtol=1e-6)


def test_polarised_pair_separates_exactly():
    rng = np.random.default_rng(2)
    d, s = rng.random((8, 8, 3)), rng.random((8, 8, 3))
    para, perp = polarised_pair(d, s, transmission=0.5)
    assert np.allclose(perp, 0.5 * d)
    dd, ss = separate_polarisation(para, perp, transmission=0.5)
    assert np.allclose(dd, d, atol=1e-15) and np.allclose(ss, s, atol=1e-15)
    para0, perp0 = polarised_pair(d, None)
    assert np.array_equal(para0, perp0)


@pytest.fixture(scope="module")
def subject_and_raw(stand_in_head):
    subj = make_subjects(stand_in_head, 1, seed=5)[0]
    colour = camera_colour()
    raw_d, raw_s = subject_raw_albedo(subj.melanin, subj.blood, subj.diffuse, subj.specular,
                                      stand_in_head.regions["eyeballs"], colour)
    return subj, raw_d, raw_s, colour


def test_raw_albedo_maps_back_to_the_subjects_linear_srgb(stand_in_head, subject_and_raw):
    subj, raw_d, raw_s, colour = subject_and_raw
    t = colour.matrix
    # skin: spectral rendering through the camera equals the subjects' table to < 1e-3
    assert np.abs(raw_d @ t.T - subj.diffuse).max() < 2e-3
    assert np.allclose(raw_s @ t.T, subj.specular, atol=1e-12)
    eyes = stand_in_head.regions["eyeballs"]
    assert np.allclose((raw_d @ t.T)[eyes], subj.diffuse[eyes], atol=1e-12)
    # a grey specular albedo is a multiple of the camera's white C^T e
    white = colour.sensitivities.T @ colour.illuminant
    assert np.allclose(np.linalg.solve(t, np.ones(3)), white)


def test_misalignment_field_is_smooth_with_the_requested_rms(stand_in_head):
    v = stand_in_head.vertices
    d = misalignment_field(v, np.random.default_rng(3), rms_mm=0.5, length_mm=40.0,
                           n_features=256)
    assert 0.3 < np.sqrt((d**2).sum(1).mean()) < 0.7
    t = stand_in_head.triangles
    strain = (np.linalg.norm(d[t[:, 0]] - d[t[:, 1]], axis=1)
              / np.linalg.norm(v[t[:, 0]] - v[t[:, 1]], axis=1))
    assert strain.max() < 0.06       # neighbours move almost together: smooth, not noise


class _RecordingRng:
    """Delegates to a Generator and records which kinds of draws were made."""

    def __init__(self, seed):
        self._g = np.random.default_rng(seed)
        self.calls = []

    def __getattr__(self, name):
        self.calls.append(name)
        return getattr(self._g, name)


def _simulate(head, raw_d, raw_s, colour, effects, rng):
    rig = build_rig(resolution=SMALL.resolution, extra_resolution=SMALL.extra_resolution,
                    distortion=effects.distortion)
    return simulate_capture(head.vertices, head.triangles, raw_d, raw_s, rig=rig, colour=colour,
                            settings=SMALL, effects=effects, rng=rng)


def test_effects_off_are_not_computed(stand_in_head, subject_and_raw, monkeypatch):
    _, raw_d, raw_s, colour = subject_and_raw

    def forbidden(*args, **kwargs):
        raise AssertionError("an effect that is off was computed")

    monkeypatch.setattr("pipeline.lightstage.dome_shading.specular_lobe", forbidden)
    monkeypatch.setattr(RayCaster, "occluded", forbidden)
    monkeypatch.setattr(lightstage_sim, "misalignment_field", forbidden)
    monkeypatch.setattr(lightstage_sim, "render_vertex_values", forbidden)
    rng = _RecordingRng(0)
    cap = _simulate(stand_in_head, raw_d, raw_s, colour, CaptureEffects.none(), rng)
    assert "poisson" not in rng.calls and "uniform" not in rng.calls
    assert cap.iso == 100 and cap.extra_images == ()
    assert all(np.array_equal(a, b) for a, b in zip(cap.parallel, cap.perpendicular))
    assert all(not np.any(c.distortion) for c in cap.cameras)


def test_effects_on_are_computed(stand_in_head, subject_and_raw):
    _, raw_d, raw_s, colour = subject_and_raw
    rng = _RecordingRng(0)
    cap = _simulate(stand_in_head, raw_d, raw_s, colour, CaptureEffects(), rng)
    assert "poisson" in rng.calls and "uniform" in rng.calls
    assert len(cap.extra_images) == 3 and len(cap.extra_images[0]) == 7
    assert all(np.any(c.distortion) for c in cap.cameras)
    spec = [p.astype(int) - q.astype(int) for p, q in zip(cap.parallel, cap.perpendicular)]
    assert all(s.max() > 1000 for s in spec)


def test_simulation_is_reproducible_and_without_noise_separates_exactly(
        stand_in_head, subject_and_raw):
    _, raw_d, raw_s, colour = subject_and_raw
    eff = dataclasses.replace(CaptureEffects.none(), specular=True)
    a = _simulate(stand_in_head, raw_d, raw_s, colour, eff, np.random.default_rng(4))
    b = _simulate(stand_in_head, raw_d, raw_s, colour, eff, np.random.default_rng(4))
    assert all(np.array_equal(x, y) for x, y in zip(a.parallel, b.parallel))
    diffuse_only = _simulate(stand_in_head, raw_d, np.zeros_like(raw_s), colour, eff,
                             np.random.default_rng(4))
    for pose in range(len(POSES)):
        # the perpendicular image does not depend on the specular albedo at all
        assert np.array_equal(a.perpendicular[pose], diffuse_only.perpendicular[pose])
        assert np.array_equal(diffuse_only.parallel[pose], diffuse_only.perpendicular[pose])
        assert np.all(a.parallel[pose] >= a.perpendicular[pose])


def test_exposure_puts_a_white_diffuser_at_the_white_level():
    colour = camera_colour()
    kappa = exposure_constant(colour, 0.5)
    white = colour.sensitivities.T @ colour.illuminant
    assert np.isclose((kappa * white).max(), 0.5)
