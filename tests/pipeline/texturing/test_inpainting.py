"""Statistical inpainting, Poisson blending and eyeball specular."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from pipeline.texturing.inpainting import (
    poisson_blend,
    replace_eyeball_specular,
    statistical_guess,
    statistical_inpaint,
)


def _low_rank_maps(head, n_samples=24, seed=0):
    """Smooth maps spanned by three fixed fields (+ a mean): exactly a rank-3 population."""
    rng = np.random.default_rng(seed)
    u = head.vertices / np.linalg.norm(head.vertices, axis=1, keepdims=True)
    fields = np.stack([u[:, 0], u[:, 1] ** 2, u[:, 2] * u[:, 1]])           # (3, n)
    coef = rng.normal(size=(n_samples, 3, 3)) * 0.1                        # per channel
    return 0.4 + np.einsum("sfc,fn->snc", coef, fields)


def _patch(head, centre, radius_mm):
    return np.linalg.norm(head.vertices - centre, axis=1) < radius_mm


def test_statistical_guess_predicts_a_hole_from_the_other_samples(stand_in_head):
    maps = _low_rank_maps(stand_in_head)
    masks = np.zeros(maps.shape[:2], bool)
    masks[4] = _patch(stand_in_head, np.array([0.0, 0.0, 90.0]), 40)
    corrupted = np.where(masks[..., None], 5.0, maps)      # garbage where masked
    guess = statistical_guess(corrupted, masks)
    # the other samples span the population exactly, so the hole is predicted exactly
    # (a model containing the sample itself would return the mean fill instead)
    assert np.abs(guess[4] - maps[4]).max() < 1e-9
    assert np.abs(guess - maps).max() < 1e-9


def test_iterated_inpainting_fills_many_holes(stand_in_head):
    maps = _low_rank_maps(stand_in_head)
    masks = np.zeros(maps.shape[:2], bool)
    rng = np.random.default_rng(1)
    for i in range(len(maps)):
        masks[i] = _patch(stand_in_head, stand_in_head.vertices[rng.integers(len(maps[0]))], 30)
    corrupted = np.where(masks[..., None], 5.0, maps)
    mean_fill = np.where(masks[..., None], 0.0, maps).sum(0) / (~masks).sum(0)[:, None]
    err_mean = np.sqrt(np.mean((np.broadcast_to(mean_fill, maps.shape) - maps)[masks] ** 2))
    out = statistical_inpaint(corrupted, masks, stand_in_head.vertices, stand_in_head.triangles,
                              iterations=2)
    assert np.array_equal(out[~masks], maps[~masks])
    assert np.sqrt(np.mean((out - maps)[masks] ** 2)) < 0.1 * err_mean
    assert np.abs(out - maps)[masks].max() < 0.03


def test_poisson_blend_keeps_data_and_fills_without_seams(stand_in_head):
    v, t = stand_in_head.vertices, stand_in_head.triangles
    truth = 0.5 + 0.002 * v[:, [0]] * np.ones((1, 3))        # a smooth ramp
    mask = _patch(stand_in_head, np.array([0.0, 0.0, 90.0]), 40)
    guess = truth + 0.2                                      # right gradients, wrong level
    out = poisson_blend(np.where(mask[:, None], np.nan, truth), guess, mask, v, t)
    assert np.array_equal(out[~mask], truth[~mask])
    # the pasted guess jumps by 0.2 across the mask border; the blend is continuous
    edges = np.vstack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    border = edges[mask[edges[:, 0]] != mask[edges[:, 1]]]
    pasted = np.where(mask[:, None], guess, truth)
    jump_pasted = np.abs(pasted[border[:, 0]] - pasted[border[:, 1]]).max()
    jump_blend = np.abs(out[border[:, 0]] - out[border[:, 1]]).max()
    step = np.abs(truth[border[:, 0]] - truth[border[:, 1]]).max()
    assert jump_pasted > 0.19 and jump_blend <= step + 1e-9
    # inside, the fill follows the guess's gradients from the border level: close to truth
    assert np.abs(out[mask] - truth[mask]).max() < 0.03


def test_statistical_inpaint_completes_every_sample(stand_in_head):
    maps = _low_rank_maps(stand_in_head, seed=2)
    masks = np.zeros(maps.shape[:2], bool)
    masks[::3] = _patch(stand_in_head, np.array([60.0, 0.0, 50.0]), 35)
    never = np.linalg.norm(stand_in_head.vertices - [0, 0, -90], axis=1) < 20
    masks[:, never] = True                  # never observed: filled smoothly from its border
    out = statistical_inpaint(np.where(masks[..., None], -1.0, maps), masks,
                              stand_in_head.vertices, stand_in_head.triangles, iterations=2)
    assert np.array_equal(out[~masks], maps[~masks])
    assert np.all(np.isfinite(out))
    assert np.abs(out - maps)[masks & ~never].max() < 0.03
    assert np.abs(out - maps)[:, never].max() < 0.06


def test_inpainting_rejects_bad_shapes(stand_in_head):
    with pytest.raises(InputError):
        statistical_guess(np.zeros((3, 10, 3)), np.zeros((3, 9), bool))


def test_eyeball_specular_is_the_95th_percentile():
    spec = np.tile(np.linspace(0, 1, 101)[:, None], (1, 3))
    eyes = np.zeros(101, bool)
    eyes[50:] = True
    out = replace_eyeball_specular(spec, eyes)
    assert np.allclose(out[~eyes], spec[~eyes])
    assert np.allclose(out[eyes], np.percentile(spec[50:, 0], 95))
    observed = np.zeros(101, bool)
    observed[50:60] = True
    out2 = replace_eyeball_specular(spec, eyes, observed)
    assert np.allclose(out2[eyes], np.percentile(spec[50:60, 0], 95))
