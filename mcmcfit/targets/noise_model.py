"""The image likelihood's scale, per image: pixel noise and the residuals' correlation area.

The image likelihood treats the face pixels as independent Gaussians of
per-channel sd ``sigma``. Neither half of that is given: a photograph's
residual against the best render of the model is not sensor noise but model
error (shape, light, albedo outside the PCA span), and it is smooth over the
face, so neighbouring pixels carry nearly the same evidence. Counting every
pixel as independent makes the posterior far too narrow (the albedo intervals
of such fits covered 7-20 % of the truth on synthetic faces); a fixed divisor
(the "temperature 40" of earlier versions) was tuned on faces drawn from the
model and means nothing on a photograph.

:func:`estimate_noise` measures both from the residual of one render (the
end of a provisional warm-up): ``sigma`` is the RMS residual over face pixels
and channels, and the correlation area ``A`` (pixels per independent residual)
is the integral of the residuals' spatial autocorrelation, ``A = sum_d rho(d)``
over the lags ``d`` inside the radius where the radially averaged correlation
first falls to zero (the effective sample size of a correlated field;
Bretherton et al. 1999, J. Climate 12:1990, eq. 30 in two dimensions). The
likelihood is then the Gaussian of ``sigma`` tempered by ``A``: the product
counts ``N / A`` effective pixels. On a face drawn from the model with white
sensor noise, ``A`` is about 1 and ``sigma`` the noise: the plain,
well-specified likelihood. This is empirical Bayes (the scale is read off the
data once, then held fixed for the kept draws), stated in ``summary.json``.

:func:`sensor_noise` measures a third number, the sd of the sensor noise in
the *encoded* image (``sensor_sigma``): a camera's noise is added before (shot
noise, nearly constant after the encoding) or after the encoding, not to the
linear intensities the render is compared with, and linearising a noisy
encoded value ``x^2.2`` biases it upward by ``1.1 * 1.2 x^0.2 sensor_sigma^2``
on average (Jensen's inequality; 1.1e-4 at ``x = 0.5`` and 1 % noise, about
one posterior sd of a region's mean albedo on a 250² face).
:func:`mcmcfit.targets.image.linearise` takes that bias off.

This module imports :mod:`albedo_model.shading.image_formation` (the encoding's
exponent), numpy, scipy.ndimage (the robust foreground) and scikit-image's
wavelet noise estimate.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from skimage.restoration import estimate_sigma

from albedo_model.shading.image_formation import GAMMA

__all__ = ["NoiseModel", "correlation_area", "estimate_noise", "fixed_noise", "robust_noise",
           "sensor_noise"]

#: Floor of the estimated pixel sd (linear): half an 8-bit step of a mid-grey in
#: linear units; a render that matches a noiseless image exactly must not make
#: the likelihood infinitely sharp.
MIN_SIGMA = 0.002

#: Bounds of the robust foreground's per-pixel occlusion prior.
MIN_OUTLIER, MAX_OUTLIER = 0.01, 0.95

#: Scale (pixels) of the Gaussian blur that makes the occlusion prior smooth.
SMOOTH_PX = 3.0


class NoiseModel(NamedTuple):
    """The scale of the image likelihood of one fit.

    Attributes
    ----------
    sigma : float
        Per-channel pixel sd (linear units).
    temperature : float
        The image log likelihood is divided by it (pixels per independent residual).
    source : {"estimated", "fixed"}
        Measured from the residuals (:func:`estimate_noise`) or given by the user.
    n_face : int
        Face pixels it was measured on (0 when fixed).
    n_effective : float
        ``n_face / temperature`` (NaN when fixed); with a robust foreground the
        pixels' summed probabilities of being the face over the temperature.
    outlier_probability : float
        The robust foreground's probability that a pixel shows something the
        face model cannot explain (0: the plain Gaussian likelihood); with a
        map, its mean over the pixels measured.
    outlier_map : (H W,) float32 array, optional
        The robust foreground's occlusion prior per pixel (estimated; not in
        :meth:`to_dict`).
    sensor_sigma : float
        Sd of the sensor noise in the encoded image (:func:`sensor_noise`; 0
        when fixed): the linear target is unbiased for it.
    """

    sigma: float
    temperature: float
    source: str = "fixed"
    n_face: int = 0
    n_effective: float = math.nan
    outlier_probability: float = 0.0
    outlier_map: np.ndarray | None = None
    sensor_sigma: float = 0.0

    @property
    def outlier_prior(self):
        """What the image likelihood takes: the per-pixel map when there is one, else the number."""
        return self.outlier_map if self.outlier_map is not None else self.outlier_probability

    def to_dict(self) -> dict:
        """Plain JSON-able dict, with the rule in words (``summary.json``)."""
        rule = ("sigma = RMS residual over the likelihood's pixels (the Gaussian sampler: the "
                "fixed interior region at the best chain's mode; the random-walk sampler: the "
                "face pixels at the end of the provisional warm-up); temperature = correlation "
                "area of the residuals (pixels per independent residual); sensor_sigma = sd "
                "of the sensor noise in the encoded image, the smaller of the residual's "
                "(divided by the encoding's slope at the render) and scikit-image's wavelet "
                "estimate over the region's bounding box; the linear target is x^2.2 - 1.32 "
                "x^0.2 sensor_sigma^2 (the expected linear value of a noisy encoded x, to "
                "second order); held fixed for the kept draws" if self.source == "estimated" else
                "sigma and temperature given by the configuration")
        if self.outlier_probability > 0.0:
            rule += ("; robust foreground: each pixel is the face (Gaussian) or, with "
                     "probability outlier_probability, an occluder (the image's colour density)"
                     + (", sigma and a smooth per-pixel occlusion prior (blur 3 px) by EM on "
                        "the residuals; outlier_probability is its mean over the region"
                        if self.source == "estimated" else ""))
        out = self._asdict()
        del out["outlier_map"]
        out["rule"] = rule
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in out.items()}


def fixed_noise(sigma: float, temperature: float,
                outlier_probability: float = 0.0) -> NoiseModel:
    """Return the noise model of given ``sigma``, ``temperature`` and outlier probability."""
    return NoiseModel(float(sigma), float(temperature), "fixed",
                      outlier_probability=float(outlier_probability))


def _autocorrelation(field: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(sum_p x(p) x(p + d), overlap count)`` for every lag d, both (2H-1, 2W-1), centred."""
    h, w = mask.shape
    shape = (2 * h - 1, 2 * w - 1)
    fx = np.fft.rfft2(field, shape)
    fm = np.fft.rfft2(mask.astype(np.float64), shape)
    acf = np.fft.fftshift(np.fft.irfft2(fx * np.conj(fx), shape))
    overlap = np.fft.fftshift(np.fft.irfft2(fm * np.conj(fm), shape))
    return acf, np.rint(overlap)


def correlation_area(residual: np.ndarray, mask: np.ndarray, *, max_radius: int | None = None,
                     min_overlap: int = 50) -> float:
    """Correlation area of a residual field over a mask: pixels per independent residual.

    Parameters
    ----------
    residual : (H, W) or (H, W, C) float array
        Residuals (channels are averaged after their autocorrelations are formed).
    mask : (H, W) bool
        Pixels that take part.
    max_radius : int, optional
        Largest lag considered (default: a quarter of the mask's smaller extent).
    min_overlap : int
        Lags with fewer overlapping pixel pairs are ignored (too noisy).

    Returns
    -------
    float >= 1
        ``sum_d rho(d)`` over lags inside the radius where the radially averaged
        correlation ``rho`` first drops to zero or below.
    """
    m = np.asarray(mask, bool)
    r = np.asarray(residual, np.float64)
    if r.ndim == 2:
        r = r[..., None]
    n = int(m.sum())
    if n < 2 * min_overlap:
        return 1.0
    rows, cols = np.nonzero(m)
    if max_radius is None:
        max_radius = max(2, int(min(np.ptp(rows), np.ptp(cols))) // 4)
    rho = np.zeros((2 * m.shape[0] - 1, 2 * m.shape[1] - 1))
    used = 0
    for c in range(r.shape[2]):
        x = np.where(m, r[..., c] - r[..., c][m].mean(), 0.0)
        acf, overlap = _autocorrelation(x, m)
        c0 = float((x * x).sum()) / n
        if c0 <= 0:
            continue
        with np.errstate(invalid="ignore", divide="ignore"):
            rho += np.where(overlap >= min_overlap, acf / np.maximum(overlap, 1) / c0, 0.0)
        used += 1
    if used == 0:
        return 1.0
    rho /= used
    cy, cx = m.shape[0] - 1, m.shape[1] - 1
    yy, xx = np.indices(rho.shape)
    radius = np.rint(np.hypot(yy - cy, xx - cx)).astype(np.int64)
    inside = radius <= max_radius
    sums = np.bincount(radius[inside], weights=rho[inside], minlength=max_radius + 1)
    counts = np.bincount(radius[inside], minlength=max_radius + 1)
    radial = sums / np.maximum(counts, 1)
    below = np.flatnonzero(radial[1:] <= 0.0)
    cut = int(below[0]) + 1 if below.size else max_radius + 1  # first radius with rho <= 0
    return float(max(1.0, sums[:cut].sum()))


def robust_noise(residual: np.ndarray, background: np.ndarray, mask: np.ndarray, *,
                 min_sigma: float = MIN_SIGMA, start: float = 0.05, smooth_px: float = SMOOTH_PX,
                 iterations: int = 100) -> tuple[float, np.ndarray, np.ndarray]:
    """EM for the robust foreground: ``(sigma, occlusion prior (H, W), face probability (H, W))``.

    Each mask pixel's residual comes from the face, ``N(0, sigma^2 I_3)``, or
    with probability ``eps_p`` from an occluder of colour density
    ``exp(background)``. EM alternates the pixels' face probabilities ``f_p``
    with ``sigma^2 = sum f d2 / (3 sum f)`` and the occlusion prior
    ``eps = G * (1 - f) / G * 1`` (a Gaussian blur of ``smooth_px`` over the
    mask, normalised): occluders are coherent regions, so a pixel's prior is its
    neighbourhood's share of occluders (a smoothness prior in the spirit of
    Egger et al. 2018's segmentation), and an isolated badly fitted pixel
    (a mole, a misfit highlight) among face pixels stays face. ``eps`` is kept
    within [:data:`MIN_OUTLIER`, :data:`MAX_OUTLIER`]; off the mask it is the
    mask's mean.

    Parameters
    ----------
    residual : (H, W, 3) float
        Target minus render.
    background : (H, W) float
        The target's background log density.
    mask : (H, W) bool
        The pixels that take part (the likelihood's region).
    """
    from scipy.ndimage import gaussian_filter

    m = np.asarray(mask, bool)
    d2 = np.sum(np.asarray(residual, np.float64)[m] ** 2, axis=1)
    bg = np.asarray(background, np.float64)[m]
    weight = gaussian_filter(m.astype(np.float64), smooth_px)
    eps = np.full(d2.shape, float(np.clip(start, MIN_OUTLIER, MAX_OUTLIER)))
    var = max(min_sigma ** 2, float(np.mean(d2)) / 3.0) if d2.size else min_sigma ** 2
    face = np.ones_like(d2)
    for _ in range(iterations):
        log_face = np.log1p(-eps) - 1.5 * math.log(2.0 * math.pi * var) - d2 / (2.0 * var)
        face = np.exp(log_face - np.logaddexp(log_face, np.log(eps) + bg))
        new_var = max(min_sigma ** 2, float(np.sum(face * d2) / max(3.0 * np.sum(face), 1e-12)))
        out = np.zeros(m.shape)
        out[m] = 1.0 - face
        new_eps = np.clip(gaussian_filter(out, smooth_px)[m] / np.maximum(weight[m], 1e-12),
                          MIN_OUTLIER, MAX_OUTLIER)
        done = abs(new_var - var) <= 1e-6 * var and float(np.max(np.abs(new_eps - eps),
                                                                  initial=0.0)) <= 1e-4
        var, eps = new_var, new_eps
        if done:
            break
    prior = np.full(m.shape, float(eps.mean()) if eps.size else MIN_OUTLIER)
    prior[m] = eps
    probability = np.ones(m.shape)
    probability[m] = face
    return math.sqrt(var), prior, probability


def estimate_noise(target: np.ndarray, render: np.ndarray, mask: np.ndarray, *,
                   usable: np.ndarray | None = None, min_sigma: float = MIN_SIGMA,
                   background: np.ndarray | None = None) -> NoiseModel:
    """Measure the likelihood's scale from one render: RMS residual and correlation area.

    Parameters
    ----------
    target, render : (H, W, 3) float arrays
        The linear target image and the linear render.
    mask : (H, W) bool
        Face pixels of the render.
    usable : (H, W) bool, optional
        Target pixels that may be used (e.g. not clipped by the camera).
    min_sigma : float
        Floor of the returned sigma.
    background : (H, W) float array, optional
        The target's background log density: a robust foreground's occluder
        density. Then sigma and the outlier probability come from
        :func:`robust_noise`, and the correlation area from the pixels more
        likely the face than not.

    Returns
    -------
    NoiseModel
        ``source="estimated"``.
    """
    m = np.asarray(mask, bool)
    if usable is not None:
        m = m & np.asarray(usable, bool)
    n = int(m.sum())
    if n == 0:
        raise ValueError("estimate_noise: no face pixel to measure the residual on")
    res = np.asarray(target, np.float64) - np.asarray(render, np.float64)
    sensor = sensor_noise(target, render, m)
    if background is not None:
        sigma, prior, face = robust_noise(res, background, m, min_sigma=min_sigma)
        area = correlation_area(res, m & (face > 0.5))
        return NoiseModel(sigma, area, "estimated", n, float(face[m].sum()) / area,
                          float(prior[m].mean()), prior.reshape(-1).astype(np.float32), sensor)
    sigma = max(float(min_sigma), float(np.sqrt(np.mean(res[m] ** 2))))
    area = correlation_area(res, m)
    return NoiseModel(sigma, area, "estimated", n, n / area, sensor_sigma=sensor)


#: Darkest encoded value at which the residual is divided by the encoding's slope
#: (below it the slope, and the residual's share of the noise, vanish).
_MIN_ENCODED = 0.05


def sensor_noise(target: np.ndarray, render: np.ndarray, mask: np.ndarray) -> float:
    """Sd of the sensor noise in the encoded (``x^(1/2.2)``) image, over ``mask``.

    Each of two estimates bounds it from above: the residual against the
    render, mapped to the encoded scale by the encoding's slope at the render
    (it also holds the model's error), and scikit-image's wavelet estimate
    (:func:`skimage.restoration.estimate_sigma`, Donoho's MAD of the finest
    diagonal detail) over the mask's bounding box (it also holds the image's
    finest texture). The smaller is returned: on a face drawn from the model
    the first is the noise, on a photograph the second.

    Parameters
    ----------
    target, render : (H, W, 3) float arrays
        The linear target image and the linear render.
    mask : (H, W) bool
        Pixels to measure on (at least one).

    Returns
    -------
    float >= 0, in encoded units (1 = full scale).
    """
    m = np.asarray(mask, bool)
    if not m.any():
        raise ValueError("sensor_noise: no pixel to measure on")
    lin = np.clip(np.asarray(render, np.float64)[m], 0.0, 1.0)
    slope = GAMMA * np.maximum(lin ** (1.0 / GAMMA), _MIN_ENCODED) ** (GAMMA - 1.0)
    res = (np.asarray(target, np.float64)[m] - np.asarray(render, np.float64)[m]) / slope
    from_residual = float(np.sqrt(np.mean(res ** 2)))
    rows, cols = np.nonzero(m)
    box = np.clip(np.asarray(target, np.float64)[rows.min():rows.max() + 1,
                                                 cols.min():cols.max() + 1], 0.0, 1.0)
    if min(box.shape[:2]) < 4:
        return from_residual
    wavelet = float(estimate_sigma(box ** (1.0 / GAMMA), channel_axis=-1, average_sigmas=True))
    return min(from_residual, wavelet)
