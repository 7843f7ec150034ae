"""Screened-Poisson stitching: gradient operator, view selection, seamlessness, real sample."""

from __future__ import annotations

import time

import numpy as np
import pytest

from albedo_model.errors import InputError
from pipeline.texturing.poisson_stitching import gradient_operator, select_views, stitch


def grid(nx: int = 21, ny: int = 17, *, jitter: float = 0.0, seed: int = 0):
    """A planar triangulated grid on [0, 1] x [0, 0.8] (z = 0), optionally jittered."""
    xs, ys = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 0.8, ny))
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    if jitter:
        rng = np.random.default_rng(seed)
        v[:, :2] += rng.uniform(-jitter, jitter, (len(v), 2)) / nx
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    t = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)]).astype(np.int32)
    return v, t


def smooth(v):
    """A smooth RGB function on the plane."""
    x, y = v[:, 0], v[:, 1]
    return np.stack([0.4 + 0.3 * np.sin(3 * x) * y, 0.5 + 0.2 * x * x, 0.3 + 0.1 * np.cos(4 * y)], 1)


def edges(t):
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def test_gradient_operator_on_linear_functions():
    v, t = grid(jitter=0.3)
    G = gradient_operator(v, t)
    a = np.array([0.7, -1.3, 0.0])
    g = (G @ (v @ a + 0.25)).reshape(3, -1).T
    np.testing.assert_allclose(g, np.broadcast_to(a, g.shape), atol=1e-9)
    # on a bent surface the interpolant's gradient is the tangential part
    vb = v.copy()
    vb[:, 2] = 0.5 * vb[:, 0] ** 2
    a = np.array([0.2, 0.5, 1.0])
    g = (gradient_operator(vb, t) @ (vb @ a)).reshape(3, -1).T
    n = np.cross(vb[t[:, 1]] - vb[t[:, 0]], vb[t[:, 2]] - vb[t[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    np.testing.assert_allclose(g, a - (n @ a)[:, None] * n, atol=1e-9)


def test_select_views_brute_force():
    rng = np.random.default_rng(1)
    v, t = grid(9, 7)
    w = rng.uniform(-0.5, 1.0, (3, len(v))).clip(0)
    sel = select_views(w, t)
    for i, tri in enumerate(t):
        conf = w[:, tri].min(axis=1)
        assert sel[i] == (np.argmax(conf) if conf.max() > 0 else -1)
    assert (sel == -1).any() and (sel >= 0).any()


def test_single_view_everywhere_valid_is_reproduced():
    v, t = grid(jitter=0.2)
    s = smooth(v)
    res = stitch(v, t, s[None], np.ones((1, len(v))))
    np.testing.assert_allclose(res.colour, s, atol=1e-9)
    assert res.residual < 1e-10 and (res.selected_view == 0).all() and res.screened.all()


def test_single_view_with_unseen_border_is_reproduced():
    v, t = grid(41, 33)
    f = 2 * smooth(v)
    seen = np.hypot(v[:, 0] - 0.5, v[:, 1] - 0.4) < 0.3
    res = stitch(v, t, f[None], seen[None].astype(float))
    assert (res.selected_view == -1).any()
    np.testing.assert_allclose(res.colour[seen], f[seen], atol=1e-4)
    # the published weighting (1.0) lets the zero-gradient border flatten the data
    paper = stitch(v, t, f[None], seen[None].astype(float), no_view_weight=1.0)
    assert np.abs(paper.colour[seen] - f[seen]).max() > 0.03


def _two_views(v, offset):
    f = smooth(v)
    x = v[:, 0]
    w0 = np.where(x <= 0.6, 1.0 - 0.5 * x, 0.0)
    w1 = np.where(x >= 0.4, 0.5 + 0.5 * x, 0.0)
    return f, np.stack([f, f + offset]), np.stack([w0, w1])


def test_two_views_with_offset_are_seamless():
    v, t = grid(31, 25, jitter=0.2)
    offset = np.array([0.2, -0.1, 0.15])
    f, colours, weights = _two_views(v, offset)
    res = stitch(v, t, colours, weights, lam=0.1)
    assert set(np.unique(res.selected_view)) == {0, 1}
    # gradients of both views agree, so the reference (view 0) fixes everything: c = f
    np.testing.assert_allclose(res.colour, f, atol=1e-8)
    # on every edge inside a selected region the stitched difference is the view's difference
    tri_of_view = [t[res.selected_view == k] for k in (0, 1)]
    for k, tris in enumerate(tri_of_view):
        e = edges(tris)
        np.testing.assert_allclose(res.colour[e[:, 0]] - res.colour[e[:, 1]],
                                   colours[k][e[:, 0]] - colours[k][e[:, 1]], atol=1e-8)
    # a naive per-vertex best-view texture has a seam of the full offset
    naive = colours[np.argmax(weights, 0), np.arange(len(v))]
    e = edges(t)
    jump = np.abs((naive[e[:, 0]] - naive[e[:, 1]]) - (f[e[:, 0]] - f[e[:, 1]])).max(axis=0)
    np.testing.assert_allclose(jump, np.abs(offset), atol=1e-12)
    # screening only where the reference view is best changes nothing here
    sel = stitch(v, t, colours, weights, reference_region="selected")
    np.testing.assert_array_equal(sel.screened, np.argmax(weights, 0) == 0)
    np.testing.assert_allclose(sel.colour, f, atol=1e-8)
    # the other view as reference shifts everything by its offset
    res1 = stitch(v, t, colours, weights, reference_view=1)
    np.testing.assert_allclose(res1.colour, f + offset, atol=1e-8)


def test_inconsistent_views_blend_without_seam():
    v, t = grid(31, 25)
    f, colours, weights = _two_views(v, np.zeros(3))
    colours[1] = 1.3 * f + 0.1  # gain and offset: gradients disagree in the overlap
    res = stitch(v, t, colours, weights, lam=0.1)
    e = edges(t)
    step = np.abs(res.colour[e[:, 0]] - res.colour[e[:, 1]]).max()
    naive = colours[np.argmax(weights, 0), np.arange(len(v))]
    naive_step = np.abs(naive[e[:, 0]] - naive[e[:, 1]]).max()
    view_step = max(np.abs(c[e[:, 0]] - c[e[:, 1]]).max() for c in colours)
    assert naive_step > 0.15  # the seam
    assert step <= view_step * 1.05  # no edge jumps more than the views' own texture does
    # the reference region keeps its texture up to a smooth shift
    left = v[:, 0] < 0.3
    dev = res.colour[left] - f[left]
    assert np.abs(dev - dev.mean(axis=0)).max() < 0.02


def test_hole_and_loose_parts_get_finite_values():
    v, t = grid(21, 17)
    f = smooth(v)
    w = np.ones((2, len(v)))
    w[1] = 0.0
    hole = np.hypot(v[:, 0] - 0.5, v[:, 1] - 0.4) < 0.15
    w[0, hole] = 0.0
    # a second grid only the non-reference view sees, a third nobody sees, one lone vertex
    v2, t2 = grid(5, 5)
    v3, t3 = grid(4, 4)
    n1, n2 = len(v), len(v) + len(v2)
    verts = np.concatenate([v, v2 + [2, 0, 0], v3 + [4, 0, 0], [[9.0, 9.0, 0.0]]])
    tris = np.concatenate([t, t2 + n1, t3 + n2])
    colours = np.zeros((2, len(verts), 3))
    weights = np.zeros((2, len(verts)))
    colours[0, :n1], weights[0, :n1] = f, w[0]
    colours[1, n1:n2], weights[1, n1:n2] = smooth(v2) + 0.3, 1.0
    colours[1, n2:] = np.nan  # invalid samples may hold anything
    res = stitch(verts, tris, colours, weights)
    assert np.isfinite(res.colour).all() and res.residual < 1e-8
    ring = ~hole & (np.hypot(v[:, 0] - 0.5, v[:, 1] - 0.4) < 0.25)
    lo, hi = f[ring].min(axis=0), f[ring].max(axis=0)
    inside = res.colour[:n1][hole]
    assert (inside >= lo - 0.02).all() and (inside <= hi + 0.02).all()
    # the part without a reference vertex keeps its own view's colours
    np.testing.assert_allclose(res.colour[n1:n2], smooth(v2) + 0.3, atol=1e-8)
    # unseen parts fall back to the mean screened colour
    np.testing.assert_allclose(res.colour[n2:], np.broadcast_to(
        f[w[0] > 0].mean(axis=0), (len(verts) - n2, 3)), atol=1e-8)


def test_bad_inputs():
    v, t = grid(5, 5)
    with pytest.raises(InputError, match="no vertex is valid"):
        stitch(v, t, np.zeros((1, len(v), 3)), np.zeros((1, len(v))))
    with pytest.raises(InputError, match="reference_view 2"):
        stitch(v, t, np.zeros((2, len(v), 3)), np.ones((2, len(v))), reference_view=2)
    with pytest.raises(InputError, match="colours must be"):
        stitch(v, t, np.zeros((2, len(v) - 1, 3)), np.ones((2, len(v))))


@pytest.mark.embree
def test_albedomm_sample(shared_data, capsys):
    from pipeline.texturing.stitch_capture import stitch_capture

    folder = shared_data / "albedomm_sample"
    start = time.perf_counter()
    run = stitch_capture(folder / "FV.mat", [folder / f"im{i}.jpg" for i in (1, 2, 3)],
                         folder / "cameras.json")
    elapsed = time.perf_counter() - start
    res = run.result
    assert np.isfinite(res.colour).all() and res.residual < 1e-8
    # Poisson blending may overshoot [0, 1] slightly at a few vertices
    assert ((res.colour > -0.1) & (res.colour < 1.1)).all()
    assert ((res.colour >= 0) & (res.colour <= 1)).mean() > 0.999
    counts = np.bincount(res.selected_view + 1, minlength=4)
    assert (counts[1:] > 10000).all()
    frontal = np.zeros(len(run.vertices), bool)
    frontal[run.triangles[res.selected_view == 0].ravel()] = True
    rmse = float(np.sqrt(((res.colour[frontal] - run.samples[0].colour[frontal]) ** 2).mean()))
    assert rmse <= 0.03
    with capsys.disabled():
        t = run.timings
        print(f"\nAlbedoMM sample stitch: {elapsed:.2f} s wall ("
              + ", ".join(f"{k} {v:.2f}" for k, v in t.items())
              + f"); RMSE vs frontal samples on {frontal.sum()} frontal vertices {rmse:.4f}")
