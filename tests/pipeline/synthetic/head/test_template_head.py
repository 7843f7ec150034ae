"""The procedural template head: symmetry, mesh validity, landmarks, regions."""

from __future__ import annotations

import numpy as np
import pytest

import pipeline.synthetic.head.head_sdf as head_sdf_module
from albedo_model.errors import InputError
from pipeline.synthetic.head.head_sdf import EYE, as_points, head_sdf
from pipeline.synthetic.head.landmarks import LANDMARK_NAMES, LFW_TLMS_NAMES
from pipeline.synthetic.head.regions import REGION_NAMES
from pipeline.synthetic.head.template_head import TemplateHead, build_template_head, mirror_points


@pytest.fixture(scope="module")
def head() -> TemplateHead:
    return build_template_head()


def _undirected_edges(t: np.ndarray) -> np.ndarray:
    e = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    return e


def test_sizes_and_types(head: TemplateHead) -> None:
    v, t = head.vertices, head.triangles
    assert 10_000 <= len(v) <= 30_000
    assert v.dtype == np.float64 and v.shape[1] == 3
    assert t.dtype == np.int32 and t.shape[1] == 3
    assert t.min() == 0 and t.max() == len(v) - 1
    assert head.symmetry.dtype == np.int64


def test_head_dimensions_are_adult_sized(head: TemplateHead) -> None:
    lo, hi = head.vertices.min(0), head.vertices.max(0)
    assert 140.0 < hi[0] - lo[0] < 190.0  # breadth incl. ears
    assert 180.0 < hi[2] - lo[2] < 240.0  # depth incl. nose
    assert 125.0 < hi[2] < 140.0  # nose tip


def test_symmetry_map_is_an_involution_onto_the_mirror_image(head: TemplateHead) -> None:
    sym, v = head.symmetry, head.vertices
    np.testing.assert_array_equal(sym[sym], np.arange(len(v)))
    assert np.abs(mirror_points(v)[sym] - v).max() < 1e-6
    mid = sym == np.arange(len(v))
    assert mid.sum() > 50
    assert np.all(v[mid, 0] == 0.0)
    # the triangulation is mirror-symmetric too (mirrored triangles reverse their winding)
    tris = {tuple(np.roll(tr, -np.argmin(tr))) for tr in head.triangles.tolist()}
    mirrored = sym[head.triangles][:, ::-1]
    assert all(tuple(np.roll(tr, -np.argmin(tr))) in tris for tr in mirrored.tolist())


def test_mesh_is_closed_oriented_outwards_and_clean(head: TemplateHead) -> None:
    v, t = head.vertices, head.triangles.astype(np.int64)
    e = _undirected_edges(t)
    # closed and consistently oriented: each directed edge once, its reverse once
    key = e[:, 0] * len(v) + e[:, 1]
    assert len(np.unique(key)) == len(key)
    rev = e[:, 1] * len(v) + e[:, 0]
    assert np.all(np.isin(rev, key))
    # divergence theorem: positive enclosed volume = outward normals; a head is ~4 litres
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert 3.0e6 < volume < 5.5e6
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    assert area.min() > 1e-4
    edge = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    assert edge.max() < 12.0
    # Euler characteristic 2: one closed surface of genus 0
    assert len(v) - len(np.unique(np.sort(e, 1), axis=0)) + len(t) == 2


def test_vertices_lie_on_the_zero_set(head: TemplateHead) -> None:
    d = np.abs(head_sdf(head.vertices))
    assert np.percentile(d, 99) < 0.01
    assert d.max() < 0.2


def test_culling_does_not_change_the_field_near_the_surface(monkeypatch) -> None:
    rng = np.random.default_rng(0)
    p = as_points(rng.uniform((-95, -110, -95), (95, 148, 138), (60_000, 3)))
    fast = head_sdf(p)
    monkeypatch.setattr(head_sdf_module, "_CULL_MARGIN", np.inf)
    monkeypatch.setattr(head_sdf_module, "_FACE_BOX", ((-np.inf,) * 3, (np.inf,) * 3))
    monkeypatch.setattr(head_sdf_module, "_EAR_BOX", ((0.0, -np.inf, -np.inf), (np.inf,) * 3))
    exact = head_sdf(p)
    near = np.abs(exact) < 2.0
    assert near.sum() > 500
    assert np.abs(fast - exact)[near].max() < 2e-3  # the zero set moves by < 2 micrometres
    np.testing.assert_array_equal(np.sign(fast), np.sign(exact))


def test_field_is_even_in_x() -> None:
    rng = np.random.default_rng(1)
    p = rng.uniform((-95, -110, -95), (95, 148, 138), (20_000, 3))
    np.testing.assert_allclose(head_sdf(p), head_sdf(mirror_points(p)), atol=1e-9)


def test_rebuild_is_identical(head: TemplateHead) -> None:
    again = build_template_head()
    np.testing.assert_array_equal(again.vertices, head.vertices)
    np.testing.assert_array_equal(again.triangles, head.triangles)
    np.testing.assert_array_equal(again.symmetry, head.symmetry)
    assert again.landmarks == head.landmarks
    for k in head.regions:
        np.testing.assert_array_equal(again.regions[k], head.regions[k])


# -- landmarks -------------------------------------------------------------------------
def test_landmark_names_cover_lfw_tlms(head: TemplateHead) -> None:
    assert set(LFW_TLMS_NAMES) <= set(head.landmarks)
    assert set(head.landmarks) == set(LANDMARK_NAMES)
    # distinct vertices, except the closed mouth's shared inner lip point (as in BFM "nomouth")
    assert head.landmarks["center.lips.upper.inner"] == head.landmarks["center.lips.lower.inner"]
    assert len(set(head.landmarks.values())) == len(head.landmarks) - 1


def test_landmarks_are_mirror_consistent(head: TemplateHead) -> None:
    sym, lm = head.symmetry, head.landmarks
    for name, i in lm.items():
        side, rest = name.split(".", 1)
        if side == "center":
            assert sym[i] == i, name
        elif side == "left":
            assert head.vertices[i, 0] > 0.0, name
            assert lm["right." + rest] == sym[i], name


def test_landmark_geometry(head: TemplateHead) -> None:
    v, lm = head.vertices, head.landmarks

    def p(name: str) -> np.ndarray:
        return v[lm[name]]

    assert lm["center.nose.tip"] == int(np.argmax(v[:, 2]))
    assert (
        p("left.eye.corner_inner")[0]
        < p("left.eye.pupil.center")[0]
        < p("left.eye.corner_outer")[0]
    )
    assert p("left.eye.bottom")[1] < p("left.eye.pupil.center")[1] < p("left.eye.top")[1]
    assert (
        p("left.eye.pupil.center")[1]
        < p("left.eyebrow.inner_lower")[1]
        < p("left.eyebrow.inner_upper")[1]
    )
    top_down = (
        "center.front.trichion", "center.nose.tip", "center.nose.attachement_to_philtrum",
        "center.lips.upper.outer", "center.lips.upper.inner", "center.lips.lower.outer",
        "center.chin.tip",
    )  # fmt: skip
    ys = [p(n)[1] for n in top_down]
    assert ys == sorted(ys, reverse=True)
    # the closed mouth's crease lies behind both lips
    assert p("center.lips.upper.inner")[2] < p("center.lips.upper.outer")[2]
    assert p("left.ear.lobule.tip")[1] < p("left.ear.tragus.tip")[1] < p("left.ear.helix.top")[1]
    # eye corners are the ends of the designed palpebral fissure
    cx, a = EYE.opening_center[0], EYE.opening_half_width
    assert abs(p("left.eye.corner_inner")[0] - (cx - a)) < 3.0
    assert abs(p("left.eye.corner_outer")[0] - (cx + a)) < 3.0


def test_landmarks_match_a_real_mean_head(head: TemplateHead, shared_data) -> None:
    """Independent truth: the Basel-named landmarks of the mean head in random-l4.h5."""
    h5py = pytest.importorskip("h5py")
    path = shared_data / "scalismo" / "random-l4.h5"
    if not path.exists():
        pytest.skip(f"{path} not found")
    with h5py.File(path, "r") as f:
        text = f["/metadata/landmarks/text"][()].decode()
    ref = {ln.split()[0]: np.array(ln.split()[2:5], float) for ln in text.strip().splitlines()}
    dist = {
        k: np.linalg.norm(head.vertices[i] - ref[k]) for k, i in head.landmarks.items() if k in ref
    }
    assert set(LFW_TLMS_NAMES) <= set(dist)
    assert max(dist[k] for k in LFW_TLMS_NAMES) < 10.0
    assert np.median(list(dist.values())) < 6.0
    assert max(dist.values()) < 16.0


# -- regions ------------------------------------------------------------------------------
def test_regions_are_present_symmetric_and_plausible(head: TemplateHead) -> None:
    r, v, lm, sym = head.regions, head.vertices, head.landmarks, head.symmetry
    assert set(r) == set(REGION_NAMES)
    for name, mask in r.items():
        assert mask.dtype == bool and mask.shape == (len(v),), name
        assert mask.any(), name
        np.testing.assert_array_equal(mask, mask[sym], err_msg=name)
    np.testing.assert_array_equal(r["skin"], ~r["eyeballs"])
    assert (
        r["eyeballs"][lm["left.eye.pupil.center"]] and r["eyeballs"][lm["right.eye.pupil.center"]]
    )
    assert r["nose"][lm["center.nose.tip"]]
    assert r["lips"][lm["center.lips.upper.outer"]] and r["lips"][lm["center.lips.lower.outer"]]
    assert r["beard"][lm["center.chin.tip"]] and not r["beard"][lm["center.nose.tip"]]
    assert r["ears"][lm["left.ear.tragus.tip"]]
    assert not (r["lips"] & r["beard"]).any() and not (r["brows"] & r["forehead"]).any()
    # eyeball vertices sit on the designed eyeball ellipsoids
    ball = v[r["eyeballs"]]
    ball[:, 0] = np.abs(ball[:, 0])
    local = (ball - EYE.center) @ np.array(
        [[np.cos(EYE.yaw), 0, np.sin(EYE.yaw)], [0, 1, 0], [-np.sin(EYE.yaw), 0, np.cos(EYE.yaw)]]
    )
    np.testing.assert_allclose(np.linalg.norm(local / EYE.radii, axis=1), 1.0, atol=0.03)


def test_resolution_is_validated() -> None:
    with pytest.raises(InputError):
        build_template_head(resolution=0.1)
