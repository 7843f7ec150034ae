"""Leave-one-out specular generalisation: Gram-space computation against a direct rebuild."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from pipeline.modelling.pca_variants import VARIANTS, build_albedo_parts
from pipeline.modelling.generalisation import plot_specular_generalisation, specular_generalisation


def _toy(seed, n_sub=5, n_vert=10):
    rng = np.random.default_rng(seed)
    sym = np.arange(n_vert) ^ 1
    diffuse = rng.uniform(0.1, 0.6, (n_sub, n_vert, 3))
    specular = 0.1 + 0.4 * diffuse[..., 1:2] + rng.normal(0, 0.03, (n_sub, n_vert, 3))
    return diffuse, specular, sym


def _direct(diffuse, specular, sym, variant, kmax):
    """Brute force: rebuild each split's models, fit by lstsq in vertex space."""
    n_sub = len(diffuse)
    fit = np.zeros((n_sub, kmax + 1))
    pred = np.zeros((n_sub, kmax + 1))
    for i in range(n_sub):
        keep = np.arange(n_sub) != i
        p = build_albedo_parts(diffuse[keep], specular[keep], sym, variant=variant)
        ys = specular[i].reshape(-1) - p.specular.mean
        yd = diffuse[i].reshape(-1) - p.diffuse.mean
        for k in range(kmax + 1):
            bs = p.specular.scaled_basis[:, :k]
            c = np.linalg.lstsq(bs, ys, rcond=None)[0] if k else np.zeros(0)
            fit[i, k] = np.sqrt(np.mean((ys - bs @ c) ** 2))
            if p.shared and k:
                cd = np.linalg.lstsq(p.diffuse.scaled_basis[:, :k], yd, rcond=None)[0]
                pred[i, k] = np.sqrt(np.mean((ys - bs @ cd) ** 2))
            else:
                pred[i, k] = np.sqrt(np.mean(ys**2))
    return fit, pred


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("augment", [True, False])
def test_gram_computation_equals_direct_rebuild(variant, augment):
    d, s, sym = _toy(0)
    sym = sym if augment else None
    res = specular_generalisation(d, s, sym, variants=(variant,))
    kmax = res["components"][-1]
    assert kmax == (4 * (2 if augment else 1)) - 1
    fit, pred = _direct(d, s, sym, variant, kmax)
    np.testing.assert_allclose(res["fit"][variant], fit, atol=1e-8)
    np.testing.assert_allclose(res["from_diffuse"][variant], pred, atol=1e-8)


def test_curves_start_equal_decrease_and_meet_at_full_rank():
    d, s, sym = _toy(1, n_sub=6)
    res = specular_generalisation(d, s, sym)
    ends = []
    for v in VARIANTS:
        curve = res["fit_mean"][v]
        assert np.all(np.diff(curve) <= 1e-12)
        ends.append((curve[0], curve[-1]))
    np.testing.assert_allclose([e[0] for e in ends], ends[0][0])   # mean only
    np.testing.assert_allclose([e[1] for e in ends], ends[0][1])   # same span at full rank


def test_plot_is_written(tmp_path):
    d, s, sym = _toy(2)
    res = specular_generalisation(d, s, sym, max_components=3)
    assert res["components"].tolist() == [0, 1, 2, 3]
    out = tmp_path / "specgen.png"
    plot_specular_generalisation(res, out)
    from PIL import Image

    with Image.open(out) as im:
        assert im.size[0] > 300 and im.size[1] > 200


def test_too_few_subjects_raise():
    d, s, sym = _toy(3, n_sub=2)
    with pytest.raises(InputError, match="at least 3"):
        specular_generalisation(d, s, sym)
