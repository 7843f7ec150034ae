"""Camera spectral model and the calibrated colour transform RAW -> linear sRGB.

A camera with spectral sensitivities ``C`` (D, 3) looking at a reflectance ``R``
(D,) under a light with spectral power ``e`` (D,) records ``raw = C^T (e * R)``.
The paper's colour transform (Smith et al. 2020, "Calibrated colour
transformation") takes raw values to linear sRGB::

    T = T_xyz2rgb @ T_raw2xyz(C) @ T_wb(C, e),   T_wb = diag(C^T e)^-1.

``T_raw2xyz`` is fitted either as in the paper (spectral Luther fit,
``C_CIE^T (C^T)^+``) or by constrained least squares on training reflectances
(colour-science's rawtoaces set) rendered under the white-balanced camera
against their CIE 1931 XYZ under D65. Either way its rows are rescaled (or
constrained) to sum to the D65 white ``w = T_xyz2rgb^-1 1`` (about
(0.9505, 1, 1.089)), so that a perfect white reflector maps to (1, 1, 1): rows
summing to 1, as the paper writes it, would turn white pink because the sRGB
matrix's rows sum to (1.205, 0.948, 0.909).

colour-science is imported lazily (it takes ~0.5-2 s) and every spectral table
is cached; cached arrays are read-only. The synthetic lightstage
(:mod:`pipeline.synthetic`) reuses this module.

This module imports nothing from the project but :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import dataclasses
from functools import cached_property, lru_cache
from typing import Literal

import numpy as np

from albedo_model.errors import InputError

__all__ = [
    "DEFAULT_CAMERA", "DEFAULT_ILLUMINANT", "CameraColour", "camera_colour",
    "camera_colour_from_spectra", "camera_sensitivities", "cie_cmfs", "d65_white_xyz", "illuminant_spd",
    "raw_to_xyz_matrix", "reference_linear_srgb", "spectral_grid", "srgb_matrix",
    "training_reflectances", "white_balance_matrix",
]

DEFAULT_CAMERA = "Nikon 5100 (NPL)"
DEFAULT_ILLUMINANT = "LED-B4"
#: Default sampling (nm): the range every shipped table covers (PMC is 400-700/10).
DEFAULT_GRID = (400.0, 700.0, 10.0)

Method = Literal["training", "luther"]


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


def spectral_grid(grid: tuple[float, float, float] = DEFAULT_GRID) -> np.ndarray:
    """Wavelengths ``start, start + step, ..., stop`` in nm, shape (D,)."""
    start, stop, step = (float(g) for g in grid)
    if not (step > 0 and stop > start):
        raise InputError(f"invalid spectral grid {grid}: need start < stop and step > 0")
    return _readonly(np.arange(start, stop + 0.5 * step, step))


def _shape(grid: tuple[float, float, float]):
    import colour

    start, stop, step = grid
    return colour.SpectralShape(start, stop, step)


def _aligned(sd, grid: tuple[float, float, float]) -> np.ndarray:
    # Sprague/cubic interpolation inside the measured range, constant outside.
    return sd.copy().align(_shape(grid), extrapolator_kwargs={"method": "Constant"}).values


@lru_cache(maxsize=16)
def camera_sensitivities(
    name: str = DEFAULT_CAMERA, grid: tuple[float, float, float] = DEFAULT_GRID
) -> np.ndarray:
    """Camera spectral sensitivities from colour-science, (D, 3) R, G, B columns.

    Parameters
    ----------
    name : str
        A key of ``colour.MSDS_CAMERA_SENSITIVITIES`` (``"Nikon 5100 (NPL)"``,
        ``"Sigma SDMerill (NPL)"``).
    grid : (start, stop, step) in nm
    """
    from colour import MSDS_CAMERA_SENSITIVITIES

    if name not in MSDS_CAMERA_SENSITIVITIES:
        known = ", ".join(sorted(MSDS_CAMERA_SENSITIVITIES))
        raise InputError(f"unknown camera {name!r}; known: {known}")
    return _readonly(_aligned(MSDS_CAMERA_SENSITIVITIES[name], grid))


@lru_cache(maxsize=16)
def illuminant_spd(
    name: str = DEFAULT_ILLUMINANT, grid: tuple[float, float, float] = DEFAULT_GRID
) -> np.ndarray:
    """Relative spectral power of a CIE illuminant or light source, (D,).

    Parameters
    ----------
    name : str
        A key of ``colour.SDS_ILLUMINANTS`` (``"D65"``, ``"LED-B4"``, ...) or of
        ``colour.SDS_LIGHT_SOURCES`` (``"Phosphor LED YAG"``, ...).
    grid : (start, stop, step) in nm
    """
    from colour import SDS_ILLUMINANTS, SDS_LIGHT_SOURCES

    for table in (SDS_ILLUMINANTS, SDS_LIGHT_SOURCES):
        if name in table:
            return _readonly(_aligned(table[name], grid))
    raise InputError(f"unknown illuminant {name!r} (not in SDS_ILLUMINANTS or SDS_LIGHT_SOURCES)")


@lru_cache(maxsize=4)
def cie_cmfs(grid: tuple[float, float, float] = DEFAULT_GRID) -> np.ndarray:
    """CIE 1931 2-degree colour matching functions, (D, 3) x-bar, y-bar, z-bar."""
    from colour import MSDS_CMFS

    return _readonly(_aligned(MSDS_CMFS["CIE 1931 2 Degree Standard Observer"], grid))


@lru_cache(maxsize=4)
def training_reflectances(grid: tuple[float, float, float] = DEFAULT_GRID) -> np.ndarray:
    """Return the 190 rawtoaces training reflectances shipped with colour-science, (190, D)."""
    from colour.characterisation import read_training_data_rawtoaces_v1

    return _readonly(_aligned(read_training_data_rawtoaces_v1(), grid).T)


@lru_cache(maxsize=1)
def srgb_matrix() -> np.ndarray:
    """``T_xyz2rgb``: XYZ (D65, Y = 1 for white) to linear sRGB, (3, 3).

    colour-science's rounded IEC 61966-2-1 matrix.
    """
    import colour

    return _readonly(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB)


def d65_white_xyz() -> np.ndarray:
    """XYZ that :func:`srgb_matrix` maps exactly to (1, 1, 1), (3,): about (0.9505, 1, 1.089)."""
    return _readonly(np.linalg.solve(srgb_matrix(), np.ones(3)))


def white_balance_matrix(sensitivities: np.ndarray, illuminant: np.ndarray) -> np.ndarray:
    """``T_wb = diag(C^T e)^-1``, (3, 3): a white reflector's raw values become 1.

    Parameters
    ----------
    sensitivities : (D, 3) array
    illuminant : (D,) array
    """
    white_raw = np.asarray(sensitivities, float).T @ np.asarray(illuminant, float)
    if np.any(white_raw <= 0):
        raise InputError("camera records no signal from the illuminant in some channel")
    return np.diag(1.0 / white_raw)


def _reference_xyz(reflectance: np.ndarray, grid: tuple[float, float, float]) -> np.ndarray:
    cmf = cie_cmfs(grid)
    d65 = illuminant_spd("D65", grid)
    return (np.asarray(reflectance, float) * d65) @ cmf / (d65 @ cmf[:, 1])


def reference_linear_srgb(
    reflectance: np.ndarray, grid: tuple[float, float, float] = DEFAULT_GRID
) -> np.ndarray:
    """Colorimetric linear sRGB of reflectances under CIE D65 (2-degree observer).

    Parameters
    ----------
    reflectance : (..., D) array
        Sampled on ``grid``.

    Returns
    -------
    (..., 3) array
        A perfect white reflector gives (1, 1, 1) to within the rounding of the
        sRGB matrix (1e-4).
    """
    return _reference_xyz(reflectance, grid) @ srgb_matrix().T


def _rows_with_sum(x: np.ndarray, y: np.ndarray, row_sums: np.ndarray) -> np.ndarray:
    """Least squares ``M`` with ``x @ M.T ~ y`` and ``M @ 1 = row_sums`` (KKT system)."""
    k = x.shape[1]
    kkt = np.zeros((k + 1, k + 1))
    kkt[:k, :k] = 2.0 * x.T @ x
    kkt[:k, k] = kkt[k, :k] = 1.0
    out = np.empty((y.shape[1], k))
    for r in range(y.shape[1]):
        rhs = np.concatenate([2.0 * x.T @ y[:, r], [row_sums[r]]])
        out[r] = np.linalg.solve(kkt, rhs)[:k]
    return out


def raw_to_xyz_matrix(
    sensitivities: np.ndarray,
    illuminant: np.ndarray | None = None,
    *,
    method: Method = "training",
    grid: tuple[float, float, float] = DEFAULT_GRID,
) -> np.ndarray:
    """``T_raw2xyz``: white-balanced camera RGB to XYZ, (3, 3), rows summing to the D65 white.

    Parameters
    ----------
    sensitivities : (D, 3) array
        Camera sensitivities on ``grid``.
    illuminant : (D,) array, optional
        Scene light; needed by ``method="training"`` (the training patches are
        rendered under it and white balanced).
    method : {"training", "luther"}
        ``"luther"``: the paper's ``C_CIE^T (C^T)^+`` with rows rescaled;
        ``"training"``: least squares over the rawtoaces reflectances with the
        row sums as an exact constraint.
    grid : (start, stop, step) in nm

    Notes
    -----
    The white-point constraint makes ``T_xyz2rgb @ T_raw2xyz @ 1 = 1`` exactly.
    On the PMC and ColorChecker skin patches the worst linear-sRGB error
    against the CIE D65 reference (Nikon 5100, LED-B4, 400-700/10 nm) is 0.028
    for ``"training"`` and 0.050 for ``"luther"``.
    """
    c = np.asarray(sensitivities, float)
    white = d65_white_xyz()
    if method == "luther":
        t = cie_cmfs(grid).T @ np.linalg.pinv(c.T)
        return t * (white / t.sum(axis=1))[:, None]
    if method == "training":
        if illuminant is None:
            raise InputError("method 'training' needs the illuminant spectrum")
        e = np.asarray(illuminant, float)
        refl = training_reflectances(grid)
        raw = ((refl * e) @ c) @ white_balance_matrix(c, e).T
        return _rows_with_sum(raw, _reference_xyz(refl, grid), white)
    raise InputError(f"unknown raw-to-XYZ method {method!r}; use 'training' or 'luther'")


@dataclasses.dataclass(frozen=True, eq=False)
class CameraColour:
    """A camera under one light and its calibrated transform to linear sRGB.

    Attributes
    ----------
    wavelengths : (D,) array, nm
    sensitivities : (D, 3) array
    illuminant : (D,) array
    t_wb, t_raw2xyz, t_xyz2rgb : (3, 3) arrays
    camera, illuminant_name, method : str
        Provenance (for metadata).
    """

    wavelengths: np.ndarray
    sensitivities: np.ndarray
    illuminant: np.ndarray
    t_wb: np.ndarray
    t_raw2xyz: np.ndarray
    t_xyz2rgb: np.ndarray
    camera: str
    illuminant_name: str
    method: str

    @cached_property
    def matrix(self) -> np.ndarray:
        """``T = T_xyz2rgb T_raw2xyz T_wb``, (3, 3): raw -> linear sRGB."""
        return _readonly(self.t_xyz2rgb @ self.t_raw2xyz @ self.t_wb)

    @cached_property
    def spectral_matrix(self) -> np.ndarray:
        """(D, 3) weights ``W`` with ``linear_srgb(R) = R @ W`` (all stages folded in)."""
        return _readonly((self.sensitivities * self.illuminant[:, None]) @ self.matrix.T)

    def metadata(self) -> dict[str, str]:
        """Provenance and the transform as strings (for a model file's metadata)."""
        import json

        return {
            "colour.camera": self.camera,
            "colour.illuminant": self.illuminant_name,
            "colour.raw_to_xyz_fit": self.method,
            "colour.wavelengths_nm": json.dumps(self.wavelengths.tolist()),
            "colour.T": json.dumps(np.round(self.matrix, 10).tolist()),
            "colour.space": "linear sRGB (IEC 61966-2-1 primaries, D65)",
        }

    def raw(self, reflectance: np.ndarray) -> np.ndarray:
        """Raw camera values ``sum_l C(l) e(l) R(l)``, (..., D) -> (..., 3)."""
        return (np.asarray(reflectance, float) * self.illuminant) @ self.sensitivities

    def linear_srgb(self, reflectance: np.ndarray) -> np.ndarray:
        """Linear sRGB ``T raw`` of reflectances, (..., D) -> (..., 3)."""
        return np.asarray(reflectance, float) @ self.spectral_matrix


@lru_cache(maxsize=8)
def camera_colour(
    camera: str = DEFAULT_CAMERA,
    illuminant: str = DEFAULT_ILLUMINANT,
    *,
    method: Method = "training",
    grid: tuple[float, float, float] = DEFAULT_GRID,
) -> CameraColour:
    """Return the calibrated camera of the synthetic lightstage (cached).

    Parameters
    ----------
    camera : str
        See :func:`camera_sensitivities`.
    illuminant : str
        See :func:`illuminant_spd`.
    method : {"training", "luther"}
        See :func:`raw_to_xyz_matrix`.
    grid : (start, stop, step) in nm
    """
    grid = tuple(float(g) for g in grid)
    c = camera_sensitivities(camera, grid)
    e = illuminant_spd(illuminant, grid)
    return CameraColour(
        wavelengths=spectral_grid(grid), sensitivities=c, illuminant=e,
        t_wb=_readonly(white_balance_matrix(c, e)),
        t_raw2xyz=_readonly(raw_to_xyz_matrix(c, e, method=method, grid=grid)),
        t_xyz2rgb=srgb_matrix(), camera=camera, illuminant_name=illuminant, method=method,
    )


def camera_colour_from_spectra(
    sensitivities: np.ndarray,
    illuminant: np.ndarray,
    *,
    camera: str,
    illuminant_name: str,
    method: Method = "training",
    grid: tuple[float, float, float] = DEFAULT_GRID,
) -> CameraColour:
    """Build a :class:`CameraColour` from given spectra.

    The spectra may come from, e.g.,
    :func:`~pipeline.lightstage.spectral_csv.read_spectral_csv`.

    Parameters
    ----------
    sensitivities : (D, 3) array
        Camera R, G, B sensitivities on ``grid``.
    illuminant : (D,) array
        Light spectral power on ``grid``.
    camera, illuminant_name : str
        Provenance for metadata.
    method : {"training", "luther"}
    grid : (start, stop, step) in nm
    """
    grid = tuple(float(g) for g in grid)
    wl = spectral_grid(grid)
    c = np.asarray(sensitivities, float)
    e = np.asarray(illuminant, float).reshape(-1)
    if c.shape != (len(wl), 3) or e.shape != (len(wl),):
        raise InputError(f"spectra must be ({len(wl)}, 3) and ({len(wl)},) on the grid {grid}; "
                         f"got {c.shape} and {e.shape}")
    return CameraColour(
        wavelengths=wl, sensitivities=_readonly(c), illuminant=_readonly(e),
        t_wb=_readonly(white_balance_matrix(c, e)),
        t_raw2xyz=_readonly(raw_to_xyz_matrix(c, e, method=method, grid=grid)),
        t_xyz2rgb=srgb_matrix(), camera=camera, illuminant_name=illuminant_name, method=method,
    )
