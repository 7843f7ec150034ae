"""Spectral skin reflectance from melanin and blood, and its linear sRGB.

Two Kubelka-Munk slabs (epidermis over dermis, black backing) with absorption
from melanin, haemoglobin and baseline tissue (the model summarised in
``docs/colour-and-skin.md`` section 3; Jacques 1998, Donner & Jensen 2006).
Units: wavelength in nm, absorption/scattering in cm^-1, thickness in cm.

Why this model and not spectra spanned by colour-science's skin patches: its
parameters (melanin fraction, blood fraction) are the physiological causes of
the facial structure we want (redder lips and cheeks, darker brows and beard
shadow, Fitzpatrick types), and it covers I-VI continuously, whereas the
shipped patches (PMC, ColorChecker, TCS13/15) are a handful of chart colours
with no handle on blood or melanin.

Haemoglobin: no licence-clean offline table exists, so :func:`hbo2_extinction`
and :func:`hb_extinction` are sums of Gaussians fitted (in log space, 390-720
nm) to Prahl's tabulated molar extinction coefficients (compiled from Gratzer
and Kollias). Reference values of that table used for the fit, in cm^-1/M
(lambda: HbO2, Hb): 414: 524280, 342596; 430: 246072, 528600; 450: 62816,
103292; 500: 20932.8, 20862; 542: 53292, 48148; 556: 34476.8, 54540;
576: 55540, 40092; 600: 3200, 14677.2; 650: 368, 3750.12; 700: 290, 1794.28.
At the table's 10 nm steps over 400-700 nm the fit is within 7 % (HbO2) and
9.5 % (Hb), RMS 3 %; at its 2 nm steps the worst errors, 9 % and 12 %, sit on
the steep flanks of the Soret band.

Colour: reflectance spectra go through :mod:`pipeline.lightstage.colour` (camera,
LED, calibrated transform). Per-vertex colours never integrate spectra: they
come from :class:`SkinColourTable`, a lookup table over (melanin, blood).

Imports only :mod:`albedo_model.errors` and :mod:`pipeline.lightstage.colour`.
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np

from albedo_model.errors import InputError
from pipeline.lightstage.colour import CameraColour, camera_colour

__all__ = [
    "FITZPATRICK_TYPES", "REFERENCE_BLOOD", "SkinColourTable", "SkinOptics", "baseline_absorption",
    "blood_absorption", "dermal_scattering", "fitzpatrick_band", "hb_extinction",
    "hbo2_extinction", "melanin_absorption", "skin_colour_table", "skin_linear_srgb",
    "skin_reflectance", "slab_reflectance", "tone_melanin",
]

# (amplitude cm^-1/M, centre nm, sigma nm) of the Gaussian fits, plus constant floors.
_HBO2_BANDS = (
    (2.786e5, 417.0, 8.10), (2.576e5, 408.9, 21.03), (2.355e4, 457.4, 14.51),
    (1.396e4, 486.5, 18.66), (3.977e4, 542.0, 12.55), (4.650e4, 576.0, 8.36),
    (1.324e4, 529.5, 36.76),
)
_HBO2_FLOOR = 294.0
_HB_BANDS = (
    (8.126e4, 445.8, 2.90), (3.707e5, 434.7, 6.70), (2.985e5, 419.4, 13.45),
    (3.747e4, 564.2, 21.76), (2.295e4, 528.1, 26.05), (4.491e3, 592.0, 58.75),
)
_HB_TAIL = (216.6, 32.05)  # amplitude at 600 nm, decay length nm
_HB_FLOOR = 929.3

HB_MOLAR_MASS = 64500.0  # g/mol
LN10 = np.log(10.0)

#: Fitzpatrick types I..VI as equal bands of skin tone t in [0, 1] (0 lightest).
FITZPATRICK_TYPES = (1, 2, 3, 4, 5, 6)


def _bands(wl: np.ndarray, bands) -> np.ndarray:
    out = np.zeros_like(wl)
    for amp, mu, sigma in bands:
        out += amp * np.exp(-0.5 * ((wl - mu) / sigma) ** 2)
    return out


def hbo2_extinction(wavelengths: np.ndarray) -> np.ndarray:
    """Molar extinction of oxy-haemoglobin, cm^-1/M (analytic fit to Prahl; 400-700 nm)."""
    wl = np.asarray(wavelengths, float)
    return _bands(wl, _HBO2_BANDS) + _HBO2_FLOOR


def hb_extinction(wavelengths: np.ndarray) -> np.ndarray:
    """Molar extinction of deoxy-haemoglobin, cm^-1/M (analytic fit to Prahl; 400-700 nm)."""
    wl = np.asarray(wavelengths, float)
    amp, tau = _HB_TAIL
    return _bands(wl, _HB_BANDS) + amp * np.exp(-(wl - 600.0) / tau) + _HB_FLOOR


def blood_absorption(
    wavelengths: np.ndarray, saturation: float = 0.75, haemoglobin_g_per_l: float = 150.0
) -> np.ndarray:
    """Absorption of whole blood, cm^-1: ``ln10 (S eps_HbO2 + (1-S) eps_Hb) c / 64500``."""
    eps = saturation * hbo2_extinction(wavelengths) + (1 - saturation) * hb_extinction(wavelengths)
    return LN10 * eps * haemoglobin_g_per_l / HB_MOLAR_MASS


def melanin_absorption(wavelengths: np.ndarray, eumelanin_share: float = 0.7) -> np.ndarray:
    """Melanosome absorption, cm^-1 (Jacques): ``b 6.6e11 l^-3.33 + (1-b) 2.9e15 l^-4.75``."""
    wl = np.asarray(wavelengths, float)
    eu = 6.6e11 * wl**-3.33
    pheo = 2.9e15 * wl**-4.75
    return eumelanin_share * eu + (1 - eumelanin_share) * pheo


def baseline_absorption(wavelengths: np.ndarray) -> np.ndarray:
    """Bloodless tissue absorption, cm^-1: ``0.244 + 85.3 exp(-(l - 154) / 66.2)``."""
    wl = np.asarray(wavelengths, float)
    return 0.244 + 85.3 * np.exp(-(wl - 154.0) / 66.2)


def dermal_scattering(wavelengths: np.ndarray) -> np.ndarray:
    """Reduced scattering of the dermis, cm^-1: ``2e12 l^-4 + 2e5 l^-1.5`` (Rayleigh + Mie)."""
    wl = np.asarray(wavelengths, float)
    return 2e12 * wl**-4 + 2e5 * wl**-1.5


def slab_reflectance(
    absorption: np.ndarray, scattering: np.ndarray, thickness: float
) -> tuple[np.ndarray, np.ndarray]:
    """Kubelka-Munk reflectance and transmittance of a slab over a black backing.

    Parameters
    ----------
    absorption, scattering : arrays, cm^-1 (broadcast together)
        ``mu_a`` and reduced scattering ``mu_s'``.
    thickness : float, cm

    Returns
    -------
    R, T : arrays
        With ``K = sqrt(mu_a (mu_a + 2 mu_s'))``, ``b = sqrt(mu_a / (mu_a + 2 mu_s'))``
        and ``D = (1+b)^2 e^{Kd} - (1-b)^2 e^{-Kd}``:
        ``R = (1 - b^2)(e^{Kd} - e^{-Kd}) / D``, ``T = 4b / D``.
    """
    mua = np.asarray(absorption, float)
    mus = np.asarray(scattering, float)
    k = np.sqrt(mua * (mua + 2 * mus))
    b = np.sqrt(mua / (mua + 2 * mus))
    # divide numerator and denominator by e^{Kd} so thick slabs do not overflow
    q = np.exp(-2 * k * thickness)
    d = (1 + b) ** 2 - (1 - b) ** 2 * q
    r = (1 - b**2) * (1 - q) / d
    t = 4 * b * np.exp(-k * thickness) / d
    return r, t


@dataclasses.dataclass(frozen=True)
class SkinOptics:
    """Fixed optical constants of the two-layer skin model (calibrated, see Notes).

    Attributes
    ----------
    epidermis_cm, dermis_cm : float
        Layer thicknesses.
    scattering_scale : float
        Multiplier of the dermal reduced scattering :func:`dermal_scattering`.
    epidermis_scattering : float
        Epidermal ``mu_s'`` as a multiple of the dermal one.
    eumelanin_share : float
        Eumelanin fraction ``beta`` of melanin.
    saturation : float
        Blood oxygen saturation ``S``.
    haemoglobin_g_per_l : float

    Notes
    -----
    Calibrated (grid search over thickness, epidermal scattering, ``beta``,
    scattering scale and blood) so that the tone scale of :func:`tone_melanin`
    follows the ISSA facial medians of ``docs/colour-and-skin.md`` from linear
    sRGB (0.494, 0.324, 0.261) down to (0.064, 0.027, 0.021) under the default
    camera and LED, passing within 0.02 of the intermediate medians, with CIELAB
    a* between 9.8 and 14.6 (facial skin: about 9-12). Departures from the
    literature values: the dermal scattering is 0.4 times Jacques' formula and
    the epidermis 130 um thick; with the unscaled formula light skin comes out
    too yellow and dark skin too grey.
    """

    epidermis_cm: float = 0.013
    dermis_cm: float = 0.20
    scattering_scale: float = 0.4
    epidermis_scattering: float = 0.5
    eumelanin_share: float = 0.9
    saturation: float = 0.75
    haemoglobin_g_per_l: float = 150.0


def skin_reflectance(
    wavelengths: np.ndarray,
    melanin: np.ndarray | float,
    blood: np.ndarray | float,
    optics: SkinOptics = SkinOptics(),
) -> np.ndarray:
    """Diffuse reflectance of skin, (..., D) for melanin and blood fractions of shape (...).

    Parameters
    ----------
    wavelengths : (D,) array, nm
    melanin : array or float
        Volume fraction of melanosomes in the epidermis, in [0, 1].
    blood : array or float
        Volume fraction of blood in the dermis, in [0, 1].
    optics : SkinOptics

    Returns
    -------
    (..., D) array in [0, 1]
        ``R = R_epi + T_epi^2 R_der / (1 - R_epi R_der)``.
    """
    wl = np.asarray(wavelengths, float)
    f_mel = np.asarray(melanin, float)[..., None]
    f_blood = np.asarray(blood, float)[..., None]
    if np.any((f_mel < 0) | (f_mel > 1)) or np.any((f_blood < 0) | (f_blood > 1)):
        raise InputError("melanin and blood fractions must lie in [0, 1]")
    base = baseline_absorption(wl)
    mus = optics.scattering_scale * dermal_scattering(wl)
    mua_epi = f_mel * melanin_absorption(wl, optics.eumelanin_share) + (1 - f_mel) * base
    mua_der = (
        f_blood * blood_absorption(wl, optics.saturation, optics.haemoglobin_g_per_l)
        + (1 - f_blood) * base
    )
    r1, t1 = slab_reflectance(mua_epi, optics.epidermis_scattering * mus, optics.epidermis_cm)
    r2, _ = slab_reflectance(mua_der, mus, optics.dermis_cm)
    return r1 + t1**2 * r2 / (1 - r1 * r2)


def skin_linear_srgb(
    melanin: np.ndarray | float,
    blood: np.ndarray | float,
    optics: SkinOptics = SkinOptics(),
    camera: CameraColour | None = None,
) -> np.ndarray:
    """Linear sRGB albedo of skin as the calibrated camera records it, (..., 3).

    Integrates spectra: for many points use :class:`SkinColourTable`.
    """
    cam = camera_colour() if camera is None else camera
    return cam.linear_srgb(skin_reflectance(cam.wavelengths, melanin, blood, optics))


@dataclasses.dataclass(frozen=True, eq=False)
class SkinColourTable:
    """Linear sRGB of skin tabulated over (log melanin, sqrt blood), bilinearly interpolated.

    Colour varies fastest at small blood fractions, hence the square-root axis.

    Attributes
    ----------
    log_melanin : (M,) array
        Uniform grid of ``ln f_mel``.
    sqrt_blood : (B,) array
        Uniform grid of ``sqrt(f_blood)``.
    rgb : (M, B, 3) array
    """

    log_melanin: np.ndarray
    sqrt_blood: np.ndarray
    rgb: np.ndarray

    def __call__(self, melanin: np.ndarray, blood: np.ndarray) -> np.ndarray:
        """Linear sRGB, (...) x (...) -> (..., 3); inputs are clipped to the table range."""
        u = self._index(np.log(np.maximum(np.asarray(melanin, float), 1e-12)), self.log_melanin)
        v = self._index(np.sqrt(np.maximum(np.asarray(blood, float), 0.0)), self.sqrt_blood)
        i0 = np.minimum(u.astype(np.int64), len(self.log_melanin) - 2)
        j0 = np.minimum(v.astype(np.int64), len(self.sqrt_blood) - 2)
        fu = (u - i0)[..., None]
        fv = (v - j0)[..., None]
        t = self.rgb
        return (
            (1 - fu) * ((1 - fv) * t[i0, j0] + fv * t[i0, j0 + 1])
            + fu * ((1 - fv) * t[i0 + 1, j0] + fv * t[i0 + 1, j0 + 1])
        )

    @staticmethod
    def _index(x: np.ndarray, grid: np.ndarray) -> np.ndarray:
        step = grid[1] - grid[0]
        return np.clip((x - grid[0]) / step, 0.0, len(grid) - 1.0)


@lru_cache(maxsize=4)
def skin_colour_table(
    optics: SkinOptics = SkinOptics(),
    melanin_range: tuple[float, float] = (0.002, 0.8),
    blood_range: tuple[float, float] = (0.0, 0.30),
    shape: tuple[int, int] = (96, 61),
) -> SkinColourTable:
    """Return the (cached) lookup table of :func:`skin_linear_srgb` under the default camera.

    Bilinear interpolation error on the default grid is below 1e-3 in linear sRGB.
    """
    log_mel = np.linspace(np.log(melanin_range[0]), np.log(melanin_range[1]), shape[0])
    sqrt_blood = np.linspace(np.sqrt(blood_range[0]), np.sqrt(blood_range[1]), shape[1])
    mm, bb = np.meshgrid(np.exp(log_mel), sqrt_blood**2, indexing="ij")
    rgb = skin_linear_srgb(mm, bb, optics)
    for a in (log_mel, sqrt_blood, rgb):
        a.setflags(write=False)
    return SkinColourTable(log_mel, sqrt_blood, rgb)


# Skin tone t -> melanin fraction. Knots calibrated (at blood 0.02, default optics,
# camera and LED) so that CIELAB L* falls linearly in t from 66.2 (linear sRGB
# 0.494 0.324 0.261) to 21.7 (0.064 0.027 0.021), the ISSA light and deep ends.
_TONE_KNOTS = np.linspace(0.0, 1.0, 9)
_TONE_LOG_MELANIN = np.log(
    np.array([0.0339, 0.0538, 0.0762, 0.1014, 0.1305, 0.1646, 0.2060, 0.2586, 0.3303])
)
#: Dermal blood fraction at which the tone scale is calibrated.
REFERENCE_BLOOD = 0.02


def tone_melanin(tone: np.ndarray | float) -> np.ndarray:
    """Epidermal melanin fraction for skin tone ``t`` in [0, 1] (0 lightest), log-interpolated."""
    t = np.asarray(tone, float)
    if np.any((t < 0) | (t > 1)):
        raise InputError("skin tone must lie in [0, 1]")
    return np.exp(np.interp(t, _TONE_KNOTS, _TONE_LOG_MELANIN))


def fitzpatrick_band(skin_type: int) -> tuple[float, float]:
    """Return the range of skin tone ``t`` covered by Fitzpatrick type I..VI (1..6)."""
    if skin_type not in FITZPATRICK_TYPES:
        raise InputError(f"Fitzpatrick type must be 1..6, got {skin_type!r}")
    return ((skin_type - 1) / 6.0, skin_type / 6.0)
