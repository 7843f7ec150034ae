"""Real SH basis: constants, scalismo's order, orthonormality, Lambert factors, light builders."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

from albedo_model import sh
from albedo_model.params import SHLight


def fibonacci_sphere(n: int) -> np.ndarray:
    """Near-uniform unit vectors (equal-area Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (1.0 + 5.0**0.5) * i
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def gauss_sphere(n_theta: int = 120) -> tuple[np.ndarray, np.ndarray]:
    """Product Gauss-Legendre x trapezoid rule on the sphere (test's own implementation)."""
    t, wt = np.polynomial.legendre.leggauss(n_theta)
    phi = np.linspace(0.0, 2.0 * np.pi, 2 * n_theta, endpoint=False)
    ct, cp = np.meshgrid(t, phi, indexing="ij")
    st = np.sqrt(1.0 - ct**2)
    dirs = np.stack([st * np.cos(cp), st * np.sin(cp), ct], -1).reshape(-1, 3)
    w = (wt[:, None] * np.full(phi.size, 2.0 * np.pi / phi.size)).reshape(-1)
    return dirs, w


def real_sh_scipy(l: int, m: int, dirs: np.ndarray) -> np.ndarray:
    """Real SH of degree l, order m from scipy's complex ones (Condon-Shortley phase)."""
    polar = np.arccos(np.clip(dirs[:, 2], -1.0, 1.0))
    azimuth = np.arctan2(dirs[:, 1], dirs[:, 0])
    y = special.sph_harm_y(l, abs(m), polar, azimuth)
    if m > 0:
        return np.sqrt(2.0) * (-1) ** m * y.real
    if m < 0:
        return np.sqrt(2.0) * (-1) ** m * y.imag
    return y.real


def test_constants_closed_forms_and_reference_values():
    assert sh.SH_N0 == pytest.approx(0.5 * np.sqrt(1 / np.pi), rel=1e-15)
    assert sh.SH_N1 == pytest.approx(0.5 * np.sqrt(3 / np.pi), rel=1e-15)
    assert sh.SH_N21 == pytest.approx(0.5 * np.sqrt(15 / np.pi), rel=1e-15)
    assert sh.SH_N20 == pytest.approx(0.25 * np.sqrt(5 / np.pi), rel=1e-15)
    assert sh.SH_N22 == pytest.approx(0.25 * np.sqrt(15 / np.pi), rel=1e-15)
    # Five-digit values quoted from scalismo-faces.
    np.testing.assert_allclose(
        [sh.SH_N0, sh.SH_N1, sh.SH_N21, sh.SH_N20, sh.SH_N22],
        [0.28209, 0.48860, 1.09255, 0.31539, 0.54627], atol=5e-6,
    )
    np.testing.assert_allclose(
        sh.LAMBERT_FACTORS, [np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5, rtol=1e-15
    )


def test_order_matches_scalismo_on_axes():
    x, y, z = np.eye(3)
    d = np.array([x, y, z, (x + y) / np.sqrt(2), (y + z) / np.sqrt(2), (x + z) / np.sqrt(2)])
    b = sh.sh_basis(d)
    n0, n1, n21, n20, n22 = sh.SH_N0, sh.SH_N1, sh.SH_N21, sh.SH_N20, sh.SH_N22
    expected = np.array([
        [n0, 0, 0, n1, 0, 0, -n20, 0, n22],            # +x
        [n0, n1, 0, 0, 0, 0, -n20, 0, -n22],           # +y
        [n0, 0, n1, 0, 0, 0, 2 * n20, 0, 0],           # +z
        [n0, n1 / 2**.5, 0, n1 / 2**.5, n21 / 2, 0, -n20, 0, 0],
        [n0, n1 / 2**.5, n1 / 2**.5, 0, 0, n21 / 2, n20 / 2, 0, -n22 / 2],
        [n0, 0, n1 / 2**.5, n1 / 2**.5, 0, 0, n20 / 2, n21 / 2, n22 / 2],
    ])
    np.testing.assert_allclose(b, expected, atol=1e-12)


def test_index_is_band_and_order_of_real_sh():
    """Y_i = +-(real SH of l = floor(sqrt i), m = i - l^2 - l), one sign per i over the sphere."""
    dirs = fibonacci_sphere(500)
    b = sh.sh_basis(dirs)
    for i in range(9):
        l = int(np.floor(np.sqrt(i)))
        m = i - l * l - l
        ref = real_sh_scipy(l, m, dirs)
        sign = np.sign(np.dot(ref, b[:, i]))
        np.testing.assert_allclose(b[:, i], sign * ref, atol=1e-10, err_msg=f"index {i}")


def test_orthonormal_on_sphere():
    dirs, w = gauss_sphere(40)
    b = sh.sh_basis(dirs)
    gram = b.T @ (b * w[:, None])
    np.testing.assert_allclose(gram, np.eye(9), atol=1e-12)
    # An independent, quadrature-free check: equal-area points (Monte-Carlo-like accuracy).
    f = sh.sh_basis(fibonacci_sphere(40000))
    np.testing.assert_allclose(4 * np.pi * f.T @ f / len(f), np.eye(9), atol=2e-3)


def test_lambert_factors_are_clamped_cosine_coefficients():
    """Funk-Hecke: projecting max(n.l, 0) onto SH gives A_l Y_i(l)."""
    ldir = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    dirs, w = gauss_sphere(400)
    coeffs = sh.sh_basis(dirs).T @ (np.maximum(dirs @ ldir, 0.0) * w)
    np.testing.assert_allclose(coeffs, sh.LAMBERT_FACTORS * sh.sh_basis(ldir), atol=2e-5)


def test_project_to_sh_recovers_coefficients():
    true = np.random.default_rng(3).normal(size=(9, 2))
    got = sh.project_to_sh(lambda d: sh.sh_basis(d) @ true, n_theta=20)
    np.testing.assert_allclose(got, true, atol=1e-12)


def test_ambient_white_shades_one():
    n = fibonacci_sphere(100)
    np.testing.assert_allclose(sh.sh_irradiance(SHLight.ambient_white().coefficients, n), 1.0,
                               atol=1e-12)


def test_directional_lobe_is_order2_clamped_cosine():
    """Shading with sh_from_directional is the order-2 clamped cosine; error bounded by 3/32."""
    ldir = np.array([-0.2, 0.4, 0.9])
    ldir = ldir / np.linalg.norm(ldir)
    intensity = np.array([1.0, 0.5, 2.0])
    n = fibonacci_sphere(20000)
    cos = n @ ldir
    shading = sh.sh_irradiance(sh.sh_from_directional(ldir, intensity), n)
    # Exact closed form E2(c) = 1/4 + c/2 + 5/32 (3c^2 - 1) (Ramamoorthi & Hanrahan 2001).
    e2 = 0.25 + 0.5 * cos + 5.0 / 32.0 * (3 * cos**2 - 1)
    np.testing.assert_allclose(shading, np.outer(e2, intensity), atol=1e-12)
    err = np.abs(shading - np.outer(np.maximum(cos, 0.0), intensity)) / intensity
    # Largest error 3/32 = 0.09375 at the terminator, mean absolute error about 3.07 %.
    assert err.max() <= 3.0 / 32.0 + 1e-12
    assert err.max() >= 3.0 / 32.0 - 1e-3
    assert 0.029 < err.mean() < 0.0315
    near_terminator = np.abs(cos) < 0.01
    assert err[near_terminator].min() > 0.088  # slope of the error is 1/2 there


def test_ambient_diffuse_is_exact_and_matches_frontal():
    np.testing.assert_allclose(sh.sh_from_ambient_diffuse(0.8, 0.2)[:, 0],
                               SHLight.frontal().coefficients[:, 0], atol=1e-12)
    L = sh.sh_from_ambient_diffuse(0.8, 0.2)
    assert L[0, 0] == pytest.approx(0.9027, abs=1e-4)
    assert L[2, 0] == pytest.approx(0.19544, abs=1e-5)
    ldir = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    n = fibonacci_sphere(300)
    got = sh.sh_irradiance(sh.sh_from_ambient_diffuse([0.1, 0.2, 0.3], 0.7, ldir), n)
    np.testing.assert_allclose(got, np.array([0.1, 0.2, 0.3]) + 0.7 * (n @ ldir)[:, None],
                               atol=1e-12)


def test_basis_components_trace_under_jit():
    d = fibonacci_sphere(64)
    f = jax.jit(lambda x, y, z: jnp.stack(sh.sh_basis_components(x, y, z), -1))
    got = f(*(jnp.asarray(d[:, i], jnp.float32) for i in range(3)))
    np.testing.assert_allclose(np.asarray(got), sh.sh_basis(d), atol=1e-6)


def test_invalid_inputs_raise():
    with pytest.raises(ValueError):
        sh.sh_basis_components(0.0, 0.0, 1.0, 10)
    with pytest.raises(ValueError):
        sh.sh_basis(np.zeros((4, 2)))
    with pytest.raises(ValueError):
        sh.sh_from_directional([0.0, 0.0, 0.0])
