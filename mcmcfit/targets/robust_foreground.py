"""The robust foreground: each pixel the face or an occluder, the label summed out.

With ``outlier_probability`` > 0 (:class:`~mcmcfit.targets.image.ImageLikelihood`
over a fixed region) each region pixel's term is
``log((1 - eps) N(I; R, sigma^2) + eps h(I)) / T`` (:func:`robust_region_terms`),
``h`` the photograph's colour density, ``eps`` a scalar or a per-pixel map (the
smooth occlusion prior :func:`mcmcfit.targets.noise_model.robust_noise`
estimates). Its derivative in the render is the Gaussian's times the pixel's
probability of being the face (:func:`robust_responsibilities`), so the
Gauss-Newton gradient and precision of the curvature are the Gaussian ones with
those weights (:func:`face_weights`), and its reverse-mode read-out is the
mixture itself (:func:`readout_weights`, :func:`missed_value`). Without it the
curvature helpers return what the plain Gaussian needs.

This module imports jax, numpy and :mod:`mcmcfit.targets.likelihoods`.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from mcmcfit.targets.likelihoods import (
    ImageArrays,
    pixel_log_normaliser,
    pixels_at,
    squared_distance,
)

__all__ = ["face_weights", "missed_value", "readout_weights", "robust_logs", "robust_pixel_values",
           "robust_region_terms", "robust_responsibilities"]


def robust_logs(sigma: float, outlier_probability, bg) -> tuple[np.ndarray, np.ndarray]:
    """Return the robust foreground's two log weights per pixel, float64 (broadcast over ``bg``).

    Returns
    -------
    face_log : ``log(1 - eps) + pixel_log_normaliser(sigma)``
    out_log : ``log eps + bg`` (``bg`` the background log density)
    """
    eps = np.asarray(outlier_probability, np.float64)
    bg = np.asarray(bg, np.float64)
    face = np.log1p(-eps) + pixel_log_normaliser(sigma)
    return np.broadcast_to(face, bg.shape).copy(), np.log(eps) + bg


def robust_region_terms(rgb, mask, target: ImageArrays, sigma, region, face_log, out_log,
                        pixels=None):
    """Row partial sums of the robust foreground likelihood over the hits of a fixed region.

    Each region pixel is the face with probability ``1 - eps`` (Gaussian of
    ``sigma`` around the render) or something the face model cannot explain
    with probability ``eps`` (hair, glasses, a hand: colour density ``h(I)``,
    the target's background density): ``log((1 - eps) N(I; R, sigma^2) + eps h(I))``,
    the occlusion label of Egger et al. (2018) summed out. A pixel the model
    explains scores about the Gaussian; an occluded one about ``log eps h(I)``
    whatever the render, so it stops pulling the fit. ``eps`` may differ per
    pixel (a smooth occlusion prior).

    Parameters
    ----------
    rgb, mask, target, sigma, region, pixels
        As :func:`region_terms`.
    face_log, out_log : (H, W) float32
        :func:`robust_logs` (the normaliser is inside the mixture).

    Returns
    -------
    rows : (P / W,) float32
        Sums of the per-pixel log mixture densities (constants included).
    counts : (P / W,) int32
        Region hits among them.
    """
    w = target.bg.shape[1]
    r = (pixels_at(region, pixels) & mask).reshape(-1, w)
    face = pixels_at(face_log, pixels) - squared_distance(rgb, target, pixels) * (0.5 / (sigma * sigma))
    val = jnp.logaddexp(face, pixels_at(out_log, pixels))
    return (jnp.sum(jnp.where(r, val.reshape(-1, w), 0.0), axis=1),
            jnp.sum(r, axis=1, dtype=jnp.int32))


def _robust_parts(colours, target, face_log, out_log, sigma):
    d2 = np.sum((np.asarray(colours, np.float64) - np.asarray(target, np.float64)) ** 2, axis=-1)
    return np.asarray(face_log, np.float64) - d2 / (2.0 * sigma * sigma), np.asarray(out_log,
                                                                                  np.float64)


def robust_pixel_values(colours: np.ndarray, target: np.ndarray, face_log: np.ndarray,
                        out_log: np.ndarray, sigma: float) -> np.ndarray:
    """Per-pixel robust log densities (float64, host): the terms :func:`robust_region_terms` sums.

    ``colours``, ``target`` (N, 3) linear; ``face_log``, ``out_log`` (N,) from
    :func:`robust_logs`.
    """
    face, out = _robust_parts(colours, target, face_log, out_log, sigma)
    return np.logaddexp(face, out)


def robust_responsibilities(colours: np.ndarray, target: np.ndarray, face_log: np.ndarray,
                            out_log: np.ndarray, sigma: float) -> np.ndarray:
    """Probability that each pixel is the face, under the robust foreground (N,) float64.

    ``(1 - eps) N / ((1 - eps) N + eps h)``: the weight of a pixel's Gaussian
    term in the gradient of :func:`robust_region_terms` (its derivative in the
    render is this times the Gaussian's). Arguments as :func:`robust_pixel_values`.
    """
    face, out = _robust_parts(colours, target, face_log, out_log, sigma)
    return np.exp(face - np.logaddexp(face, out))



def face_weights(lik, pixels: np.ndarray | None, colours: np.ndarray,
                 target: np.ndarray) -> np.ndarray | None:
    """Each of ``pixels``' probability of being the face (N,), or None for a Gaussian foreground.

    ``pixels`` row-major indices (None: every pixel); ``colours``, ``target`` (N, 3) linear.
    """
    if not lik.robust:
        return None
    face_log, out_log = lik.robust_logs(pixels)
    return robust_responsibilities(colours, target, face_log, out_log, lik.sigma)


def readout_weights(lik, pixels: np.ndarray, hit: np.ndarray,
                    capacity: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Per-pixel weights (and occluder offsets) of the reverse-mode read-out, padded to ``capacity``.

    Returns
    -------
    weight : (capacity,) float32
        Gaussian: ``1 / (sigma^2 T)`` on the hits; robust: ``1 / T``; 0 elsewhere.
    outlier : (capacity,) float32 or None
        Robust: ``out_log - face_log`` (:func:`robust_logs`), the occluder's log
        density relative to the Gaussian's peak.
    """
    n = hit.shape[0]
    weight = np.zeros(capacity, np.float32)
    if not lik.robust:
        weight[:n] = np.where(hit, 1.0 / (lik.sigma * lik.sigma * lik.temperature), 0.0)
        return weight, None
    weight[:n] = np.where(hit, 1.0 / lik.temperature, 0.0)
    face_log, out_log = lik.robust_logs(pixels)
    outlier = np.zeros(capacity, np.float32)
    outlier[:n] = out_log - face_log
    return weight, outlier


def missed_value(lik, d2: np.ndarray, outlier: np.ndarray | None) -> float:
    """Return the read-out's terms of region pixels the render misses (coloured as the background).

    ``d2`` (M,) squared distances of the targets to the background colour;
    ``outlier`` their offsets from :func:`readout_weights` (None: Gaussian).
    """
    inv_var = 1.0 / (lik.sigma * lik.sigma)
    if outlier is None:
        return -0.5 * inv_var * float(np.sum(d2)) / lik.temperature
    return float(np.sum(np.logaddexp(-0.5 * inv_var * np.asarray(d2, np.float64),
                                     np.asarray(outlier, np.float64)))) / lik.temperature
