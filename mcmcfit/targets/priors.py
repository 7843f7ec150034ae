"""Priors over the fit parameters: normalised densities of the parameters as stored.

Every factor is a fully normalised density with respect to Lebesgue measure on
the :class:`~albedo_model.params.RenderParameter` fields the proposals move
(the measure their ``log_q_ratio`` refers to), so log-normal factors carry
their ``-log x`` Jacobian. Factors:

======================  ================================================================
model coefficients      shape, albedo (shared ``momo.albedo``), expression: i.i.d. N(0, 1)
                        (the reference's prior; it has no other factor)
pose angles             yaw, pitch, roll ~ N(0, sigma) each (weak: 0.75 / 0.5 / 0.3 rad)
translation             t_x, t_y ~ N(0, 300 mm)
distance                d = view_z - t_z ~ log-normal(median 1000 mm, log-sd 1)
focal length            f ~ log-normal(median 7.5 sensor units, log-sd 1)
principal point         pp_x, pp_y ~ N(0, 0.5) (NDC)
SH light                each coefficient ~ N(frontal, sigma_band^2), sigma 1 / 0.5 / 0.5
colour transform        gain_c ~ log-normal(1, 0.5); contrast ~ N(1, 0.3);
                        offset_c ~ N(0, 0.1)
specular exponent       e ~ log-normal(median 20, log-sd 0.5)
directional light       (only when it is on) strength_c ~ log-normal(median 0.5, log-sd 1);
                        direction ~ von Mises-Fisher(towards the camera, kappa 2) on the
                        sphere, a density in (azimuth, elevation) with its cos(elevation)
======================  ================================================================

``pose.scaling``, the view, near/far and the sensor are never sampled and have
no factor. The directional light is sampled as an azimuth, an elevation and an
RGB strength (:meth:`~albedo_model.params.DirectionalLight.angles`), and its
factor is a density of those: the walks and Gaussian moves work in them.

This module imports only :mod:`albedo_model.params` and numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from albedo_model.params import RenderParameter, SHLight

__all__ = ["LogPrior", "PriorConfig", "directional_prior", "lognormal_logpdf", "normal_logpdf",
           "std_normal_logpdf"]

_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def normal_logpdf(x: float, mean: float, sigma: float) -> float:
    """``log N(x; mean, sigma^2)``."""
    z = (x - mean) / sigma
    return -_HALF_LOG_2PI - math.log(sigma) - 0.5 * z * z


def lognormal_logpdf(x: float, median: float, log_sigma: float) -> float:
    """Density of x > 0 with ``log x ~ N(log median, log_sigma^2)`` (``-inf`` for x <= 0)."""
    if not x > 0.0:
        return -math.inf
    lx = math.log(x)
    return normal_logpdf(lx, math.log(median), log_sigma) - lx


def std_normal_logpdf(c: np.ndarray) -> float:
    """``sum_i log N(c_i; 0, 1)``; 0 for an empty vector."""
    c = np.asarray(c, np.float64).reshape(-1)
    return float(-c.shape[0] * _HALF_LOG_2PI - 0.5 * float(c @ c))


@dataclass(frozen=True)
class PriorConfig:
    """Scales of the weak priors (see the module table; angles in rad, lengths in mm)."""

    yaw_sigma: float = 0.75
    pitch_sigma: float = 0.5
    roll_sigma: float = 0.3
    translation_sigma: float = 300.0
    distance_median: float = 1000.0
    distance_log_sigma: float = 1.0
    focal_median: float = 7.5
    focal_log_sigma: float = 1.0
    principal_point_sigma: float = 0.5
    light_band_sigma: tuple[float, ...] = (1.0, 0.5, 0.5)
    gain_log_sigma: float = 0.5
    contrast_sigma: float = 0.3
    offset_sigma: float = 0.1
    specular_median: float = 20.0
    specular_log_sigma: float = 0.5
    directional_median: float = 0.5
    directional_log_sigma: float = 1.0
    direction_kappa: float = 2.0


def directional_prior(angles, intensity, config: PriorConfig) -> tuple[float, np.ndarray, np.ndarray]:
    """Log density of a directional light in ``(azimuth, elevation, strength r, g, b)``.

    Returns the value, its gradient (5,) and the diagonal of its negative
    Hessian (5,), floored at 1e-6 (a precision for Gauss-Newton steps). The
    direction's factor is ``kappa/(4 pi sinh kappa) exp(kappa d_z) cos(el)`` with
    ``d_z = cos(az) cos(el)``; each strength is log-normal.
    """
    az, el = (float(a) for a in angles)
    k = float(config.direction_kappa)
    ca, sa, ce, se = math.cos(az), math.sin(az), math.cos(el), math.sin(el)
    if ce <= 0.0:
        return -math.inf, np.zeros(5), np.full(5, 1e-6)
    log_c = math.log(k / (4.0 * math.pi * math.sinh(k))) if k > 0 else -math.log(4.0 * math.pi)
    value = log_c + k * ca * ce + math.log(ce)
    grad = np.zeros(5)
    hess = np.zeros(5)
    grad[0], grad[1] = -k * sa * ce, -k * ca * se - se / ce
    hess[0], hess[1] = k * ca * ce, k * ca * ce + 1.0 / (ce * ce)
    m, s2 = config.directional_median, config.directional_log_sigma ** 2
    for i, x in enumerate(np.asarray(intensity, np.float64).reshape(3)):
        value += lognormal_logpdf(float(x), m, config.directional_log_sigma)
        if x > 0:
            z = math.log(x) - math.log(m)
            grad[2 + i] = -z / (s2 * x) - 1.0 / x
            hess[2 + i] = (1.0 - z - s2) / (s2 * x * x)
    return value, grad, np.maximum(hess, 1e-6)


class LogPrior:
    """``log p(params)``: the sum of the factors of :meth:`terms`.

    Parameters
    ----------
    config : PriorConfig, optional
    """

    def __init__(self, config: PriorConfig | None = None):
        self.config = config or PriorConfig()
        self._frontal = SHLight.frontal().coefficients

    def light_gaussian(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Return the SH light prior as ``(mean (k, 3), sd (k, 3))`` (independent Gaussians)."""
        c = self.config
        mean = np.zeros((k, 3))
        m = min(k, self._frontal.shape[0])
        mean[:m] = self._frontal[:m]
        band = np.floor(np.sqrt(np.arange(k))).astype(int)
        sig = np.asarray(c.light_band_sigma, np.float64)[np.minimum(band, len(c.light_band_sigma) - 1)]
        return mean, np.repeat(sig[:, None], 3, axis=1)

    def _light(self, coeffs: np.ndarray) -> float:
        L = np.asarray(coeffs, np.float64)
        mean, sd = self.light_gaussian(L.shape[0])
        z = (L - mean) / sd
        return float(-L.size * _HALF_LOG_2PI - np.sum(np.log(sd)) - 0.5 * np.sum(z * z))

    def terms(self, params: RenderParameter) -> dict[str, float]:
        """Each factor's log density, by name (``shape``, ``yaw``, ``distance``, ...)."""
        c = self.config
        p = params
        tx, ty, tz = p.pose.translation
        ct = p.color_transform
        out = {
            "shape": std_normal_logpdf(p.momo.shape),
            "albedo": std_normal_logpdf(p.momo.albedo),
            "expression": std_normal_logpdf(p.momo.expression),
            "yaw": normal_logpdf(p.pose.yaw, 0.0, c.yaw_sigma),
            "pitch": normal_logpdf(p.pose.pitch, 0.0, c.pitch_sigma),
            "roll": normal_logpdf(p.pose.roll, 0.0, c.roll_sigma),
            "translation_x": normal_logpdf(tx, 0.0, c.translation_sigma),
            "translation_y": normal_logpdf(ty, 0.0, c.translation_sigma),
            "distance": lognormal_logpdf(p.view.translation[2] - tz, c.distance_median,
                                         c.distance_log_sigma),
            "focal_length": lognormal_logpdf(p.camera.focal_length, c.focal_median,
                                             c.focal_log_sigma),
            "principal_point_x": normal_logpdf(p.camera.principal_point[0], 0.0,
                                               c.principal_point_sigma),
            "principal_point_y": normal_logpdf(p.camera.principal_point[1], 0.0,
                                               c.principal_point_sigma),
            "light": self._light(p.environment_map.coefficients),
            "color_transform_gain": sum(lognormal_logpdf(g, 1.0, c.gain_log_sigma) for g in ct.gain),
            "color_transform_contrast": normal_logpdf(ct.contrast, 1.0, c.contrast_sigma),
            "color_transform_offset": sum(normal_logpdf(o, 0.0, c.offset_sigma) for o in ct.offset),
            "specular_exponent": lognormal_logpdf(p.specular_exponent, c.specular_median,
                                                  c.specular_log_sigma),
        }
        dl = p.directional_light
        if dl.enabled:
            out["directional_light"] = directional_prior(dl.angles(), dl.diffuse, c)[0]
        return out

    def __call__(self, params: RenderParameter) -> float:
        """Total log prior (``-inf`` outside the support, never NaN)."""
        v = math.fsum(self.terms(params).values())
        return -math.inf if math.isnan(v) else v
