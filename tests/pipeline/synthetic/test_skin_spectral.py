"""Spectral skin model: haemoglobin fit, Kubelka-Munk slabs, Fitzpatrick calibration, table."""

import numpy as np
import pytest

from albedo_model.errors import InputError
from pipeline.synthetic import skin_spectral as ss

# Prahl's tabulated molar extinction (cm^-1/M), HbO2 and Hb, 400-700 nm every 10 nm.
PRAHL = np.array([
    (400, 266232, 223296), (410, 466840, 303956), (420, 480360, 407560), (430, 246072, 528600),
    (440, 102580, 413280), (450, 62816, 103292), (460, 44480, 23388.8), (470, 33209.2, 16156.4),
    (480, 26629.2, 14550), (490, 23684.4, 16684), (500, 20932.8, 20862), (510, 20035.2, 25773.6),
    (520, 24202.4, 31589.6), (530, 39956.8, 39036.4), (540, 53236, 46592), (550, 43016, 53412),
    (560, 32613.2, 53788), (570, 44496, 45072), (580, 50104, 37020), (590, 14400.8, 28324.4),
    (600, 3200, 14677.2), (610, 1506, 9443.6), (620, 942, 6509.6), (630, 610, 5148.8),
    (640, 442, 4345.2), (650, 368, 3750.12), (660, 319.6, 3226.56), (670, 294, 2795.12),
    (680, 277.6, 2407.92), (690, 276, 2051.96), (700, 290, 1794.28),
])

# ISSA facial medians, linear sRGB (docs/colour-and-skin.md section 4)
ISSA = {
    "ITA 62": (0.498, 0.322, 0.271), "ITA 25": (0.376, 0.204, 0.128),
    "ITA -15": (0.213, 0.098, 0.048), "ITA -60": (0.092, 0.040, 0.024),
    "deepest": (0.061, 0.028, 0.019),
}


def _lab(rgb):
    import colour

    from pipeline.lightstage.colour import srgb_matrix

    to_xyz = np.linalg.inv(srgb_matrix())
    white = colour.XYZ_to_xy(to_xyz @ np.ones(3))
    return colour.XYZ_to_Lab(np.asarray(rgb) @ to_xyz.T, white)


def test_haemoglobin_fit_follows_prahl_table():
    wl = PRAHL[:, 0]
    rel_o = ss.hbo2_extinction(wl) / PRAHL[:, 1] - 1
    rel_d = ss.hb_extinction(wl) / PRAHL[:, 2] - 1
    assert np.abs(rel_o).max() < 0.08
    assert np.abs(rel_d).max() < 0.10
    assert np.sqrt(np.mean(rel_o**2)) < 0.05 and np.sqrt(np.mean(rel_d**2)) < 0.05
    fine = np.arange(400.0, 440.0, 1.0)
    assert 410 <= fine[np.argmax(ss.hbo2_extinction(fine))] <= 418  # Soret peak 414 nm
    assert 428 <= fine[np.argmax(ss.hb_extinction(fine))] <= 436    # 430-434 nm


def test_slab_conserves_energy_without_absorption_and_tends_to_kubelka_munk_limit():
    mus = np.array([10.0, 100.0])
    r, t = ss.slab_reflectance(np.array([1e-9, 1e-9]), mus, 0.05)
    np.testing.assert_allclose(r + t, 1.0, atol=1e-4)
    mua = np.array([0.5, 3.0])
    r_inf, t_inf = ss.slab_reflectance(mua, mus, 100.0)
    b = np.sqrt(mua / (mua + 2 * mus))
    np.testing.assert_allclose(r_inf, (1 - b) / (1 + b), rtol=1e-12)
    assert np.all(t_inf < 1e-12)
    r, t = ss.slab_reflectance(mua, mus, 0.02)
    assert np.all(r + t < 1)


def test_fitzpatrick_range_ends():
    light = ss.skin_linear_srgb(ss.tone_melanin(0.0), ss.REFERENCE_BLOOD)
    dark = ss.skin_linear_srgb(ss.tone_melanin(1.0), ss.REFERENCE_BLOOD)
    np.testing.assert_allclose(light, [0.50, 0.32, 0.27], atol=0.02)
    np.testing.assert_allclose(dark, [0.06, 0.03, 0.02], atol=0.006)


@pytest.mark.parametrize("name", ["ITA 25", "ITA -15", "ITA -60"])
def test_tone_scale_passes_near_issa_medians(name):
    tones = np.linspace(0, 1, 201)
    rgb = ss.skin_linear_srgb(ss.tone_melanin(tones), ss.REFERENCE_BLOOD)
    err = np.abs(rgb - np.array(ISSA[name])).max(axis=1)
    assert err.min() < 0.02


def test_colour_is_monotone_in_melanin_and_redder_with_blood():
    tones = np.linspace(0, 1, 50)
    rgb = ss.skin_linear_srgb(ss.tone_melanin(tones), ss.REFERENCE_BLOOD)
    assert np.all(np.diff(rgb, axis=0) < 0)
    lab = _lab(rgb)
    assert np.all(np.diff(lab[:, 0]) < 0)
    assert np.all((lab[:, 1] > 8) & (lab[:, 1] < 15))   # facial a* about 9-12
    blood = np.array([0.01, 0.02, 0.05, 0.1])
    rgb_b = ss.skin_linear_srgb(0.05, blood)
    ratio = rgb_b[:, 0] / rgb_b[:, 1]
    assert np.all(np.diff(ratio) > 0)


def test_lookup_table_matches_spectral_model():
    table = ss.skin_colour_table()
    rng = np.random.default_rng(1)
    mel = np.exp(rng.uniform(np.log(0.01), np.log(0.7), 300))
    blood = rng.uniform(0.0, 0.25, 300)
    np.testing.assert_allclose(table(mel, blood), ss.skin_linear_srgb(mel, blood), atol=1e-3)
    assert table(mel.reshape(20, 15), blood.reshape(20, 15)).shape == (20, 15, 3)


def test_fitzpatrick_bands_partition_tone_range():
    bands = [ss.fitzpatrick_band(k) for k in ss.FITZPATRICK_TYPES]
    assert bands[0][0] == 0.0 and bands[-1][1] == 1.0
    assert all(a[1] == b[0] for a, b in zip(bands, bands[1:]))
    with pytest.raises(InputError):
        ss.fitzpatrick_band(7)


def test_invalid_fractions_raise():
    with pytest.raises(InputError):
        ss.skin_reflectance(np.array([500.0]), 1.5, 0.02)
    with pytest.raises(InputError):
        ss.tone_melanin(-0.1)
