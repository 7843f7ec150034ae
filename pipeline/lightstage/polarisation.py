"""Polarised diffuse/specular separation (Smith et al. 2020, "Data capture"; Ma et al. 2007).

Every LED carries a linear polariser tuned so that light reflected specularly
towards the photometric camera keeps one plane of polarisation. Subsurface
(diffuse) reflection depolarises. With a linear polariser in front of the
camera, ideal filters give

    I_perp = t D                (crossed: specular blocked, diffuse halved)
    I_para = t D + S            (aligned: specular passes, diffuse halved)

with ``t`` the polariser's transmission of unpolarised light (0.5 for an
ideal polariser). Hence ``S = I_para - I_perp`` and ``D = I_perp / t``.
Noise makes ``S`` slightly negative where there is no specular reflection; the
difference is kept signed (clipping would bias dim regions upwards).

Imports only :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.errors import InputError

__all__ = ["IDEAL_TRANSMISSION", "polarised_pair", "separate_polarisation"]

#: Transmission of unpolarised light through an ideal linear polariser.
IDEAL_TRANSMISSION = 0.5


def _check_t(transmission: float) -> float:
    t = float(transmission)
    if not 0.0 < t <= 1.0:
        raise InputError(f"polariser transmission must lie in (0, 1], got {transmission}")
    return t


def polarised_pair(diffuse: np.ndarray, specular: np.ndarray | None, *,
                   transmission: float = IDEAL_TRANSMISSION) -> tuple[np.ndarray, np.ndarray]:
    """Simulate the photometric image pair of a scene's diffuse and specular radiance.

    This is the forward model.

    Parameters
    ----------
    diffuse : (..., 3) float array
        Unpolarised (diffuse) radiance as an unfiltered camera would record it.
    specular : (..., 3) float array or None
        Polarisation-preserving (specular) radiance; ``None`` for a scene
        without specular reflection (the parallel image is then a copy).
    transmission : float

    Returns
    -------
    parallel, perpendicular : (..., 3) float arrays
    """
    t = _check_t(transmission)
    perp = t * np.asarray(diffuse)
    if specular is None:
        return perp.copy(), perp
    spec = np.asarray(specular)
    if spec.shape != perp.shape:
        raise InputError(f"diffuse {perp.shape} and specular {spec.shape} differ in shape")
    return perp + spec, perp


def separate_polarisation(parallel: np.ndarray, perpendicular: np.ndarray, *,
                          transmission: float = IDEAL_TRANSMISSION
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Diffuse and specular images from a parallel/perpendicular pair.

    Parameters
    ----------
    parallel, perpendicular : (H, W, 3) float arrays
        Linear raw images on one scale (e.g. value / 65535).
    transmission : float
        Polariser transmission of unpolarised light.

    Returns
    -------
    diffuse : (H, W, 3) float64
        ``perpendicular / transmission``.
    specular : (H, W, 3) float64
        ``parallel - perpendicular`` (signed).
    """
    t = _check_t(transmission)
    para = np.asarray(parallel, np.float64)
    perp = np.asarray(perpendicular, np.float64)
    if para.shape != perp.shape:
        raise InputError(f"parallel {para.shape} and perpendicular {perp.shape} images differ "
                         "in shape")
    return perp / t, para - perp
