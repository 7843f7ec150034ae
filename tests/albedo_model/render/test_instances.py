"""Block updates of float32 instances against full float64 instances (within float32 rounding)."""

from __future__ import annotations

import numpy as np
import pytest

from albedo_model.errors import InputError
from albedo_model.pca import PCAPart
from albedo_model.render.instances import InstanceUpdater, coefficients_for


def part(seed: int, d: int = 600, k: int = 30, scale: float = 5.0) -> PCAPart:
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((d, k)))
    return PCAPart(rng.normal(0, 10, d), q, (scale / (1 + np.arange(k))) ** 2 * d)


def test_block_update_matches_full_instance():
    a = part(0)
    up = InstanceUpdater()
    rng = np.random.default_rng(1)
    c = rng.standard_normal(a.rank)
    inst = up.instance([((a,), c)])
    assert inst.dtype == np.float32
    np.testing.assert_allclose(inst, a.instance(c), rtol=1e-6, atol=1e-4)
    count = 0
    for step in range(40):
        new = c.copy()
        start = (10 * step) % a.rank
        new[start:start + 10] += rng.normal(0, 0.3, len(new[start:start + 10]))
        inst, count = up.update([((a,), c, new)], inst, count)
        c = new
    assert count == 40
    np.testing.assert_allclose(inst, a.instance(c), rtol=1e-5, atol=2e-4)


def test_unchanged_returns_same_object_and_scattered_index():
    a = part(2)
    up = InstanceUpdater()
    c = np.zeros(a.rank)
    inst = up.instance([((a,), c)])
    same, count = up.update([((a,), c, c.copy())], inst, 5)
    assert same is inst and count == 5
    new = c.copy()
    new[[1, 7, 20]] = (0.5, -1.0, 2.0)  # not a contiguous block
    got, count = up.update([((a,), c, new)], inst, 5)
    assert count == 6
    np.testing.assert_allclose(got, a.instance(new), rtol=1e-5, atol=2e-4)


def test_stacked_parts_share_coefficients_and_sums_of_terms():
    a, b, e = part(3), part(4), part(5, k=6)
    up = InstanceUpdater()
    rng = np.random.default_rng(6)
    c, ce = rng.standard_normal(a.rank), rng.standard_normal(e.rank)
    stacked = up.instance([((a, b), c)])
    np.testing.assert_allclose(stacked, np.concatenate([a.instance(c), b.instance(c)]),
                               rtol=1e-6, atol=1e-4)
    new = c.copy()
    new[10:20] += 1.0
    got, _ = up.update([((a, b), c, new)], stacked, 0)
    np.testing.assert_allclose(got, np.concatenate([a.instance(new), b.instance(new)]),
                               rtol=1e-5, atol=2e-4)
    # shape + expression: a sum of two terms with their own coefficients
    total = up.instance([((a,), c), ((e,), ce)])
    new_e = ce.copy()
    new_e[2] = 3.0
    got, _ = up.update([((a,), c, new), ((e,), ce, new_e)], total, 0)
    np.testing.assert_allclose(got, a.instance(new) + e.instance(new_e), rtol=1e-5, atol=2e-4)


def test_refresh_and_large_changes_recompute_in_full():
    a = part(7)
    up = InstanceUpdater(refresh_every=3)
    c = np.zeros(a.rank)
    inst = up.instance([((a,), c)])
    counts = []
    for step in range(4):
        new = c.copy()
        new[step] = 1.0
        inst, count = up.update([((a,), c, new)], inst, counts[-1] if counts else 0)
        counts.append(count)
        c = new
    assert counts == [1, 2, 0, 1]
    # after a refresh the instance is the float64 one within float32 rounding (no drift)
    full = np.ones(a.rank)
    inst, count = up.update([((a,), c, full)], inst, 1)
    assert count == 0
    exact = a.instance(full)
    np.testing.assert_allclose(inst, exact, rtol=0, atol=4 * np.finfo(np.float32).eps
                               * np.abs(exact).max())


def test_coefficients_for_checks_rank_and_missing_parts():
    a = part(8, k=5)
    np.testing.assert_array_equal(coefficients_for(a, [1.0, 2.0], "shape"), [1, 2, 0, 0, 0])
    with pytest.raises(InputError, match="rank 5"):
        coefficients_for(a, np.ones(6), "shape")
    with pytest.raises(InputError, match="no expression part"):
        coefficients_for(None, [0.0, 1.0], "expression")
    assert coefficients_for(None, [0.0, 0.0], "expression").shape == (0,)
    with pytest.raises(InputError, match="non-finite"):
        coefficients_for(a, [np.nan], "shape")


def test_plan_gives_block_deltas_of_the_transposed_basis():
    a, b = part(9), part(10)
    up = InstanceUpdater(refresh_every=10)
    old = np.zeros(a.rank)
    new = old.copy()
    new[[3, 4, 9]] = (1.0, -2.0, 0.5)
    assert up.plan((a, b), old, old.copy(), 0) is None
    idx, delta = up.plan((a, b), old, new, 0)
    np.testing.assert_array_equal(idx, [3, 4, 9])
    bt = up.transposed((a, b))
    assert bt.shape == (a.rank, a.dim + b.dim) and bt.dtype == np.float32
    moved = np.concatenate([a.instance(old), b.instance(old)]) + delta @ bt[idx]
    np.testing.assert_allclose(moved, np.concatenate([a.instance(new), b.instance(new)]),
                               rtol=1e-5, atol=2e-4)
    assert up.plan((a, b), old, new, 9) == "full"  # refresh due
    assert up.plan((a, b), old, np.ones(a.rank), 0) == "full"  # most coefficients changed
