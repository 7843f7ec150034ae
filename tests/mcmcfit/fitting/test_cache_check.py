"""--check-cache: every cached product equals a fresh computation over every move kind, and a
dependency removed from the one cache table is caught."""

from __future__ import annotations

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.params import Block, DirectionalLight
from albedo_model.render.cache_table import ATOMIC_BLOCKS, STAGE_DEPS
from albedo_model.render.renderer import Renderer
from albedo_model.shading.image_formation import encode_gamma
from mcmcfit.fitting.cache_check import CacheMismatchError
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.fit import fit
from mcmcfit.sampling.kernel import ACCEPTED, REJECTION_STAGES

pytestmark = pytest.mark.embree

# one chain in this process: the tests below patch the cache table of this process. The
# random-walk schedule: every move kind touches a few blocks, so each table entry is
# exercised alone (the Gaussian sampler's moves touch every block at once).
CONFIG = FitConfig(sampler="random-walk", steps=400, warmup_steps=0, landmark_steps=100,
                   thin=5, sigma_lm=2.0, check_cache=True, chains=1, parallel=False,
                   mala_weight=0.5)


@pytest.fixture(scope="module")
def case():
    model = small_face_model()
    truth = scene(64, 64, yaw=0.25, pitch=-0.1)
    image, clicks = synthetic_target(model, truth)
    return model, image, clicks


def test_check_cache_passes_over_every_move_kind(case):
    model, image, clicks = case
    res = fit(image, clicks, model, config=CONFIG, seed=11)
    rec = res.records(2)[0]
    # every kind of move of the image stage was proposed, and moves touching every
    # block were accepted (so each cached stage was rebuilt and checked at least once)
    kinds = set(res.acceptance)
    for kind in ("yaw", "pitch", "roll", "distance", "focal", "translation", "shape",
                 "expression", "albedo", "albedo-caricature", "albedo-conditional",
                 "light-albedo", "color-transform", "sh-spatial", "sh-bands", "sh-intensity",
                 "sh-perturb", "sh-colour", "light-conditional", "gain-light", "mala",
                 "specular-exponent"):
        assert any(k.startswith(kind) for k in kinds), (kind, sorted(kinds))
    names = rec.proposal_names
    touched = Block.NONE
    for i in np.flatnonzero(rec.rejected_by == ACCEPTED):
        name = names[rec.proposal[i]]
        touched |= next(b for prefix, b in _PREFIX_BLOCKS if name.startswith(prefix))
    assert touched == Block.ALL & ~Block.DIRECTIONAL, touched  # the walks keep the light off
    # the unchecked fit takes exactly the same path
    plain = fit(image, clicks, model, config=CONFIG.replace(check_cache=False), seed=11)
    np.testing.assert_array_equal(plain.records(2)[0].log_lik_img, rec.log_lik_img)
    assert len(REJECTION_STAGES) == 6


def test_check_cache_passes_over_the_gaussian_sampler(case):
    model, image, clicks = case
    cfg = FitConfig(steps=120, warmup_steps=40, landmark_steps=100, sigma_lm=2.0,
                    check_cache=True, chains=1, parallel=False, mode_rounds=1, mode_steps=3,
                    hmc_weight=0.2, hmc_leapfrog=2)
    res = fit(image, clicks, model, config=cfg, seed=11)
    kinds = set(res.acceptance)
    for kind in ("pcn", "gaussian-geometry", "gaussian-albedo", "gaussian-shading",
                 "geometry-walk", "geometry-wide", "hmc", "albedo-offset-conditional",
                 "contrast-albedo-exchange", "light-conditional"):
        assert any(k.startswith(kind) for k in kinds), (kind, sorted(kinds))
    assert sum(s.accepted for s in res.acceptance.values()) > 0


def test_check_cache_passes_with_the_directional_light_and_its_shadows(case):
    """The Gaussian sampler with the directional light sampled (``effects="sh+directional"``).

    The face is rendered under a side light with cast shadows and noise. The
    light's angles and strength are separate blocks: the shadow cache is keyed
    on the angles alone, so a strength move (the SH light's exact conditional,
    accepted here every time) reuses the shadow; the check compares each step
    with a fresh render that casts every shadow ray again.
    """
    model = case[0]
    truth = scene(64, 64, yaw=0.25, pitch=-0.1)._replace(
        directional_light=DirectionalLight.from_angles(0.6, 0.3, (0.5, 0.45, 0.4),
                                                       shininess=20.0))
    renderer = Renderer(model, shadows=True, directional_specular_map=True, threads=1)
    out = renderer.render(truth)
    noisy = np.clip(out.image + np.random.default_rng(0).normal(0.0, 0.01, out.image.shape), 0, 1)
    image = np.where(out.mask[..., None], np.asarray(encode_gamma(noisy), np.float64), 0.35)
    names, px, vis = renderer.landmarks(out.state)
    clicks = {n: q for n, q, ok in zip(names, px, vis) if ok}
    cfg = FitConfig(steps=100, warmup_steps=30, landmark_steps=100, sigma_lm=2.0,
                    check_cache=True, chains=1, parallel=False, mode_rounds=1, mode_steps=3,
                    hmc_weight=0.2, hmc_leapfrog=2, effects="sh+directional")
    res = fit(image, clicks, model, config=cfg, seed=5)
    assert res.stopping["effects"]["decision"] == "sh+directional"
    assert res.acceptance["light-conditional"].accepted > 0


_PREFIX_BLOCKS = (
    ("yaw", Block.POSE | Block.CAMERA), ("pitch", Block.POSE | Block.CAMERA),
    ("roll", Block.POSE | Block.CAMERA), ("distance", Block.POSE | Block.CAMERA),
    ("translation", Block.POSE), ("focal", Block.CAMERA),
    ("shape", Block.SHAPE), ("expression", Block.EXPRESSION),
    ("light-albedo", Block.LIGHT | Block.ALBEDO), ("albedo", Block.ALBEDO),
    ("light-conditional", Block.LIGHT), ("gain-light", Block.COLOR_TRANSFORM | Block.LIGHT),
    ("mala", Block.SHAPE | Block.EXPRESSION | Block.POSE | Block.CAMERA),
    ("color-transform", Block.COLOR_TRANSFORM), ("sh-", Block.LIGHT),
    ("specular-exponent", Block.SPECULAR_EXPONENT),
)


@pytest.mark.parametrize("stage,block", [
    ("geometry", Block.EXPRESSION), ("raycast", Block.SHAPE), ("albedo", Block.ALBEDO),
    ("light", Block.LIGHT), ("shading", Block.SPECULAR_EXPONENT),
    ("landmarks", Block.CAMERA), ("albedo_system", Block.COLOR_TRANSFORM),
    ("light_data", Block.ALBEDO), ("light_system", Block.SPECULAR_EXPONENT),
])
def test_a_dependency_removed_from_the_table_is_caught(case, monkeypatch, stage, block):
    model, image, clicks = case
    assert STAGE_DEPS[stage] & block
    monkeypatch.setitem(STAGE_DEPS, stage, STAGE_DEPS[stage] & ~block)
    with pytest.raises(CacheMismatchError, match="differs from a fresh computation") as err:
        fit(image, clicks, model, config=CONFIG, seed=11)
    assert "cached" in str(err.value) and "step" in str(err.value)


def test_the_table_names_only_blocks():
    for stage, deps in STAGE_DEPS.items():
        assert deps and all(b in Block.ALL for b in ATOMIC_BLOCKS if deps & b), stage
