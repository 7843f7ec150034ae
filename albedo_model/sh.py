"""Real spherical harmonics (bands 0-2) in scalismo's order, Lambert factors, light builders.

Index ``i`` is band ``l = floor(sqrt(i))`` and order ``m = i - l^2 - l``; the nine
basis functions of a unit direction (x, y, z) are::

    0: N0                1: N1 y             2: N1 z             3: N1 x
    4: N21 x y           5: N21 y z          6: N20 (2z^2 - x^2 - y^2)
    7: N21 x z           8: N22 (x^2 - y^2)

with N0 = 1/2 sqrt(1/pi), N1 = 1/2 sqrt(3/pi), N21 = 1/2 sqrt(15/pi),
N20 = 1/4 sqrt(5/pi), N22 = 1/4 sqrt(15/pi) (scalismo-faces
``numerics/SphericalHarmonics.scala``). A light is a radiance environment map
``L`` (K, 3); the Lambert shading of a normal n is ``sum_i A_i Y_i(n) L_i`` with
``A = [pi, 2pi/3 x3, pi/4 x5]`` (no 1/pi). The legacy ``.rps`` order is handled
by the ``.rps`` reader, not here.

Every function works on NumPy arrays; :func:`sh_basis_components` is plain
arithmetic and also works on JAX arrays inside ``jit``.

This module imports nothing from the project.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = [
    "SH_N0", "SH_N1", "SH_N21", "SH_N20", "SH_N22", "SH_NORMALISATION", "LAMBERT_FACTORS",
    "MAX_SH_COEFFICIENTS", "sh_basis_components", "sh_basis", "sh_irradiance",
    "project_to_sh", "sh_from_directional", "sh_from_ambient_diffuse",
    "clamped_cosine_order2",
]

SH_N0 = 0.5 * np.sqrt(1.0 / np.pi)
SH_N1 = 0.5 * np.sqrt(3.0 / np.pi)
SH_N21 = 0.5 * np.sqrt(15.0 / np.pi)
SH_N20 = 0.25 * np.sqrt(5.0 / np.pi)
SH_N22 = 0.25 * np.sqrt(15.0 / np.pi)

#: Normalisation constant of each of the nine basis functions, in index order.
SH_NORMALISATION = np.array(
    [SH_N0, SH_N1, SH_N1, SH_N1, SH_N21, SH_N21, SH_N20, SH_N21, SH_N22], dtype=np.float64
)
#: Lambert (clamped-cosine convolution) factor of each coefficient, in index order.
LAMBERT_FACTORS = np.array(
    [np.pi] + [2.0 * np.pi / 3.0] * 3 + [np.pi / 4.0] * 5, dtype=np.float64
)
MAX_SH_COEFFICIENTS = 9


def sh_basis_components(x, y, z, n: int = 9) -> tuple:
    """Evaluate the first ``n`` basis functions at unit directions, one array per function.

    Parameters
    ----------
    x, y, z : arrays of one shape (NumPy, JAX or scalars)
        Components of unit directions (not renormalised here).
    n : int
        Number of coefficients, 0..9.

    Returns
    -------
    tuple of ``n`` arrays, each broadcast to the shape of ``x``; entry 0 is the
    constant ``N0`` times ``ones_like(x)``.
    """
    if not 0 <= n <= MAX_SH_COEFFICIENTS:
        raise ValueError(f"n must be in 0..{MAX_SH_COEFFICIENTS}, got {n}")
    basis = (
        lambda: SH_N0 + 0.0 * x,
        lambda: SH_N1 * y,
        lambda: SH_N1 * z,
        lambda: SH_N1 * x,
        lambda: SH_N21 * (x * y),
        lambda: SH_N21 * (y * z),
        lambda: SH_N20 * (2.0 * z * z - x * x - y * y),
        lambda: SH_N21 * (x * z),
        lambda: SH_N22 * (x * x - y * y),
    )
    return tuple(f() for f in basis[:n])


def sh_basis(directions: np.ndarray, n: int = 9) -> np.ndarray:
    """Basis matrix of unit directions.

    Parameters
    ----------
    directions : (..., 3) float array
        Unit vectors (x, y, z), any frame (the light's frame).
    n : int
        Number of coefficients, 0..9.

    Returns
    -------
    (..., n) float64 array
    """
    d = np.asarray(directions, dtype=np.float64)
    if d.shape[-1:] != (3,):
        raise ValueError(f"directions must have shape (..., 3), got {d.shape}")
    comps = sh_basis_components(d[..., 0], d[..., 1], d[..., 2], n)
    if n == 0:
        return np.zeros(d.shape[:-1] + (0,))
    return np.stack(comps, axis=-1)


def sh_irradiance(coefficients: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Lambert shading ``sum_{i<min(K,9)} A_i Y_i(n) L_i`` of unit normals.

    Parameters
    ----------
    coefficients : (K, C) or (K,) float array
        Radiance environment map ``L`` in scalismo's order.
    normals : (..., 3) float array
        Unit normals in the light's (world) frame.

    Returns
    -------
    (..., C) or (...) float64 array
        The factor multiplying the albedo (1 for ``ambient_white``).
    """
    L = np.asarray(coefficients, dtype=np.float64)
    k = min(L.shape[0], MAX_SH_COEFFICIENTS)
    basis = sh_basis(normals, k) * LAMBERT_FACTORS[:k]
    return basis @ L[:k]


def _sphere_quadrature(n_theta: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre in cos(theta) x uniform phi; exact for degree < 2 n_theta."""
    t, w_t = np.polynomial.legendre.leggauss(n_theta)
    n_phi = 2 * n_theta
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    s = np.sqrt(1.0 - t * t)
    dirs = np.stack(
        [np.outer(s, np.cos(phi)), np.outer(s, np.sin(phi)), np.outer(t, np.ones(n_phi))], -1
    ).reshape(-1, 3)
    weights = np.outer(w_t, np.full(n_phi, 2.0 * np.pi / n_phi)).reshape(-1)
    return dirs, weights


def project_to_sh(
    function: Callable[[np.ndarray], np.ndarray], n: int = 9, *, n_theta: int = 200
) -> np.ndarray:
    """Coefficients ``f_i = integral f(w) Y_i(w) dw`` of a function on the unit sphere.

    Uses a product Gauss-Legendre (in cos theta) x uniform (in phi) rule with
    ``n_theta x 2 n_theta`` points; exact for polynomials of degree < 2 n_theta,
    so smooth functions converge fast and kinked ones (clamped cosines) to ~1e-5.

    Parameters
    ----------
    function : callable
        Maps (N, 3) float64 unit directions to (N,) or (N, C) values.
    n : int
        Number of coefficients, 0..9.
    n_theta : int
        Quadrature resolution in the polar angle.

    Returns
    -------
    (n,) or (n, C) float64 array
        Plain SH projection. For a radiance map ``L`` whose Lambert shading should
        equal a given irradiance ``E``, divide the projection of ``E`` by
        :data:`LAMBERT_FACTORS`.
    """
    dirs, weights = _sphere_quadrature(n_theta)
    values = np.asarray(function(dirs), dtype=np.float64)
    basis = sh_basis(dirs, n) * weights[:, None]
    return basis.T @ values


def sh_from_directional(direction, intensity=1.0) -> np.ndarray:
    """Radiance coefficients of a distant point light: ``L_i = intensity Y_i(l)``.

    By the Funk-Hecke theorem the clamped cosine ``max(n.l, 0)`` has SH
    coefficients ``A_l Y_i(l)``, so with the Lambert factors built into the
    shading these coefficients shade a normal n with the order-2 approximation
    of ``intensity * max(n.l, 0)`` (see :func:`clamped_cosine_order2`).

    Parameters
    ----------
    direction : (3,) float array
        Direction towards the light (world frame); normalised here.
    intensity : float or (C,) float array
        Irradiance of the light on a surface facing it (e.g. RGB).

    Returns
    -------
    (9, C) float64 array (``C = 1`` for a scalar intensity).
    """
    ldir = np.asarray(direction, dtype=np.float64).reshape(3)
    norm = np.linalg.norm(ldir)
    if not norm > 0:
        raise ValueError("direction must be non-zero")
    y = sh_basis(ldir / norm, 9)
    inten = np.atleast_1d(np.asarray(intensity, dtype=np.float64))
    return np.outer(y, inten)


def sh_from_ambient_diffuse(ambient=0.8, diffuse=0.2, direction=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Bands 0-1 light whose shading is exactly ``ambient + diffuse (n.l)``.

    ``L_0 = ambient / (pi N0)`` and ``L_{1m} = diffuse l_m / (2pi/3 N1)``; the
    defaults with l = +z are scalismo's ``SH.frontal`` (L0 = 0.9027, L2 = 0.19544,
    cf. :meth:`albedo_model.params.SHLight.frontal`). Note the shading is linear,
    not clamped: back-facing normals get ``ambient - diffuse |n.l|``.

    Parameters
    ----------
    ambient, diffuse : float or (C,) float array
    direction : (3,) float array
        Direction towards the light; normalised here.

    Returns
    -------
    (9, C) float64 array (bands 2 are zero).
    """
    ldir = np.asarray(direction, dtype=np.float64).reshape(3)
    norm = np.linalg.norm(ldir)
    if not norm > 0:
        raise ValueError("direction must be non-zero")
    ldir = ldir / norm
    amb = np.atleast_1d(np.asarray(ambient, dtype=np.float64))
    dif = np.atleast_1d(np.asarray(diffuse, dtype=np.float64))
    c = amb.shape[0] if amb.shape[0] > 1 else dif.shape[0]
    L = np.zeros((9, c))
    L[0] = amb / (LAMBERT_FACTORS[0] * SH_N0)
    for i, comp in ((1, ldir[1]), (2, ldir[2]), (3, ldir[0])):
        L[i] = dif * comp / (LAMBERT_FACTORS[1] * SH_N1)
    return L


def clamped_cosine_order2(cos_angle):
    """Order-2 SH approximation of ``max(cos, 0)`` as a function of the cosine.

    ``E2(c) = 1/4 + c/2 + 5/32 (3c^2 - 1)`` (Ramamoorthi & Hanrahan 2001). Its
    largest error, 3/32 = 0.09375, is at the terminator (c = 0); at c = +-1 it is
    1/16 and at c = +-8/15 the error is -0.0396.
    """
    c = np.asarray(cos_angle, dtype=np.float64)
    return 0.25 + 0.5 * c + 5.0 / 32.0 * (3.0 * c * c - 1.0)
