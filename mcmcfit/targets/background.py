"""The colour-histogram background model of the image likelihood (scalismo's HistogramRGB).

This module imports only numpy and :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError

__all__ = ["ColourHistogram", "colour_histogram", "occluder_log_density"]


class ColourHistogram(NamedTuple):
    """A 3-D colour histogram over [0, 1]^3 with ``bins`` bins per channel.

    Attributes
    ----------
    counts : (B, B, B) int64
    total : int
    bins : int
    """

    counts: np.ndarray
    total: int
    bins: int

    def bin_index(self, colours: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bin of each colour per channel: ``min(floor(c B), B - 1)`` (c clipped to [0, 1])."""
        c = np.clip(np.asarray(colours, np.float64).reshape(-1, 3), 0.0, 1.0)
        i = np.minimum(np.floor(c * self.bins).astype(np.int64), self.bins - 1)
        return i[:, 0], i[:, 1], i[:, 2]

    def log_density(self, colours: np.ndarray) -> np.ndarray:
        """Piecewise-constant density: ``log(count / total) + 3 log B``.

        Parameters
        ----------
        colours : (..., 3) float array in [0, 1]

        Returns
        -------
        (...,) float64; ``-inf`` in empty bins.
        """
        shape = np.asarray(colours).shape[:-1]
        r, g, b = self.bin_index(colours)
        with np.errstate(divide="ignore"):
            out = np.log(self.counts[r, g, b] / self.total) + 3.0 * math.log(self.bins)
        return out.reshape(shape)

    def smoothed_log_density(self, colours: np.ndarray, sigma: float, *,
                             block: int = 4096) -> np.ndarray:
        """Log density of the histogram convolved with isotropic Gaussian noise ``N(0, sigma^2 I)``.

        Each bin is a uniform box of probability ``count / total``; convolved with
        the noise it becomes a product over channels of
        ``(Phi((hi - c) / sigma) - Phi((lo - c) / sigma)) / width``. The result is a
        proper density of the same variable as the foreground pixel model (a true
        colour observed through the same noise), and it never exceeds the
        Gaussian's peak ``(2 pi)^(-3/2) sigma^-3``: it is a mixture of densities
        each bounded by that peak. So a face pixel the model renders exactly
        always scores above the background, whatever the histogram's bin size,
        whereas the raw histogram can exceed the Gaussian's peak in the bins
        where the face's own colours pile up (one bin holding 5 % of the pixels
        at 25 bins is ``0.05 x 25^3 = 781`` against the peak ``797`` at sigma = 0.043).

        Parameters
        ----------
        colours : (..., 3) float array
        sigma : float > 0
            Per-channel noise, the pixel model's sigma.
        block : int
            Colours evaluated per block (bounds memory to ``block x bins^2`` floats).

        Returns
        -------
        (...,) float64, finite for every colour.
        """
        from scipy.special import ndtr

        c = np.asarray(colours, np.float64)
        shape = c.shape[:-1]
        c = c.reshape(-1, 3)
        b = self.bins
        edges = np.linspace(0.0, 1.0, b + 1)
        p = (self.counts / self.total).reshape(b, b * b)
        # only distinct colours need evaluating (8-bit images repeat many)
        uniq, inverse = np.unique(c, axis=0, return_inverse=True)
        dens = np.empty(uniq.shape[0])
        for start in range(0, uniq.shape[0], block):
            u = uniq[start:start + block]
            k = [(ndtr((edges[None, 1:] - u[:, ch:ch + 1]) / sigma)
                  - ndtr((edges[None, :-1] - u[:, ch:ch + 1]) / sigma)) * b for ch in range(3)]
            t = (k[0] @ p).reshape(-1, b, b)  # sum over red bins: (n, green, blue)
            t = np.einsum("njk,nj->nk", t, k[1])
            dens[start:start + block] = np.einsum("nk,nk->n", t, k[2])
        with np.errstate(divide="ignore"):
            out = np.log(np.maximum(dens, 1e-300))
        return out[inverse.reshape(-1)].reshape(shape)


def colour_histogram(colours: np.ndarray, *, bins: int = 25,
                     weights: np.ndarray | None = None) -> ColourHistogram:
    """Histogram of colours in [0, 1]^3.

    Parameters
    ----------
    colours : (..., 3) float array
        Values must lie in [0, 1] (checked; NaN rejected).
    bins : int
        Bins per channel (>= 1).
    weights : (...,) array, optional
        Only colours with weight > 1e-4 count (scalismo uses the alpha channel).

    Raises
    ------
    InputError
        Colours outside [0, 1], no colour counted, or bad ``bins``.
    """
    bins = int(bins)
    if bins < 1:
        raise InputError(f"histogram bins must be >= 1, got {bins}")
    c = np.asarray(colours, np.float64).reshape(-1, 3)
    if weights is not None:
        c = c[np.asarray(weights, np.float64).reshape(-1) > 1e-4]
    if c.shape[0] == 0:
        raise InputError("colour histogram needs at least one colour")
    if not np.all((c >= 0.0) & (c <= 1.0)):
        raise InputError("colour histogram: colours must lie in [0, 1]")
    h = ColourHistogram(np.zeros((bins,) * 3, np.int64), int(c.shape[0]), bins)
    r, g, b = h.bin_index(c)
    np.add.at(h.counts, (r, g, b), 1)
    return h


def occluder_log_density(image: np.ndarray, outside: np.ndarray, *, bins: int = 25,
                         sigma: float | None = None) -> np.ndarray:
    """Log density (H, W) of every pixel's colour under the colours outside the face.

    The robust foreground's occluder model: what covers a face (hair,
    glasses, a hand, a scarf) is most likely coloured like something else in
    the photograph, so its density is the histogram of the pixels outside the
    face region (smoothed with ``sigma`` as the background is), not of the
    whole image, where the face's own colours pile up and would make every
    badly fitted skin pixel (a freckle, stubble) look like an occluder. With
    fewer than 100 pixels outside, the whole image's histogram is used.

    Parameters
    ----------
    image : (H, W, 3) float in [0, 1]
        The target as compared (linear or encoded).
    outside : (H, W) or (H W,) bool
        Pixels outside the face region.
    bins : int
    sigma : float, optional
        Noise the histogram is convolved with (:meth:`ColourHistogram.smoothed_log_density`).
    """
    img = np.asarray(image, np.float64)
    out = np.asarray(outside, bool).reshape(img.shape[:2])
    hist = colour_histogram(img, bins=bins, weights=out if out.sum() >= 100 else None)
    return hist.log_density(img) if sigma is None else hist.smoothed_log_density(img, sigma)
