"""The target photograph for the image likelihood: linearisation, background, evaluation.

Colour space (one choice, used everywhere in mcmcfit): the model is shaded in
**linear sRGB** and compared there. Targets are 8-bit sRGB photographs read as
value/255; they are linearised with AlbedoMM's pure power, ``I_lin = I^2.2``
(not the piecewise sRGB curve), before comparison, for the background
histogram (built from the linearised target pixels, so that foreground and
background are densities of the same variable) and for the SH light solver.
The pixel sigma (0.043 by default) is therefore in linear units.

The one exception is a model whose colour is a gamma-encoded sRGB texture
(BFM 2017; :func:`albedo_model.io.colour_space.model_colour_space`): its
colour is taken as the camera's sRGB values, as the reference does, so the
render is compared with the photograph's encoded values
(``prepare_image_target(..., colour="srgb")``) and everything above reads
them instead of the linearised ones.

Background: the reference scores each face pixel against the raw colour
histogram of the target, ``log(count / total) + 3 log B``. Where the face's own
colours pile up (the face is a large part of the image and its colours are
concentrated), that density exceeds the Gaussian foreground's peak
``(2 pi)^(-3/2) sigma^-3`` (797 at sigma = 0.043, reached by one bin holding 5 %
of the pixels), so even a perfectly rendered face pixel scores below
background and the posterior prefers faces that are too small. With
``smooth_sigma`` the histogram is convolved with the pixel noise: a density of
the same noisy colour as the foreground, which never exceeds its peak
(:meth:`~mcmcfit.targets.background.ColourHistogram.smoothed_log_density`); fits
use it by default (:attr:`mcmcfit.fitting.config.FitConfig.background`).

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.shading.image_formation`,
:mod:`mcmcfit.targets.background` and :mod:`mcmcfit.targets.likelihoods`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.errors import InputError
from albedo_model.shading.image_formation import GAMMA, Shaded
from mcmcfit.targets.background import ColourHistogram, colour_histogram
from mcmcfit.targets.likelihoods import (
    ImageArrays,
    collective_terms,
    finish_collective,
    finish_independent,
    finish_region,
    finish_trimmed,
    independent_terms,
    region_terms,
    trimmed_terms,
)
from mcmcfit.targets.robust_foreground import robust_logs, robust_region_terms

__all__ = [
    "IMAGE_LIKELIHOODS",
    "ImageLikelihood",
    "ImageTarget",
    "linearise",
    "prepare_image_target",
]

#: Kinds of image likelihood :class:`ImageLikelihood` evaluates.
IMAGE_LIKELIHOODS = ("independent", "collective", "trimmed")


def linearise(image: np.ndarray, sensor_sigma: float = 0.0) -> np.ndarray:
    """Pure-power linearisation ``x^2.2`` of an image in [0, 1] (clipped; 0 stays 0).

    Parameters
    ----------
    image : (..., 3) float array, gamma-encoded (value/255 for 8-bit files)
    sensor_sigma : float
        Sd of zero-mean noise in the encoded values. ``x^2.2`` of a noisy ``x``
        overestimates the noiseless intensity by ``0.5 g (g - 1) x^(g - 2)
        sensor_sigma^2`` on average (``g = 2.2``, second order in the noise);
        that is subtracted (the result floored at 0). 0 gives the plain power.

    Returns
    -------
    (..., 3) float64 linear RGB in [0, 1]
    """
    x = np.clip(np.asarray(image, np.float64), 0.0, 1.0)
    with np.errstate(divide="ignore"):
        log_x = np.log(np.maximum(x, 1e-300))
        lin = np.where(x > 0.0, np.exp(GAMMA * log_x), 0.0)
        if sensor_sigma > 0.0:
            bias = 0.5 * GAMMA * (GAMMA - 1.0) * float(sensor_sigma) ** 2 * \
                np.where(x > 0.0, np.exp((GAMMA - 2.0) * log_x), 0.0)
            lin = np.maximum(lin - bias, 0.0)
    return lin


@dataclass(frozen=True, eq=False)
class ImageTarget:
    """A prepared target image.

    Attributes
    ----------
    linear : (H, W, 3) float64, host
        The target in the space the render is compared in: linearised, or
        with ``colour == "srgb"`` the encoded photograph (clipped to [0, 1]).
    histogram : ColourHistogram
        Background model, built from all pixels of ``linear``.
    arrays : ImageArrays
        Device copies: the RGB planes of ``linear`` (H, W) float32 and the
        background log density of every pixel (H, W) float32.
    colour : {"linear", "srgb"}
        The comparison space: ``"linear"`` (linear sRGB, the default) or
        ``"srgb"`` (the photograph's encoded values, for sRGB-texture models).
    """

    linear: np.ndarray
    histogram: ColourHistogram
    arrays: ImageArrays
    colour: str = "linear"

    @property
    def height(self) -> int:
        """Image height H in pixels."""
        return int(self.linear.shape[0])

    @property
    def width(self) -> int:
        """Image width W in pixels."""
        return int(self.linear.shape[1])


def prepare_image_target(image: np.ndarray, *, bins: int = 25,
                         smooth_sigma: float | None = None,
                         colour: str = "linear", sensor_sigma: float = 0.0) -> ImageTarget:
    """Linearise a photograph (unless ``colour="srgb"``) and build its background histogram.

    Parameters
    ----------
    image : (H, W, 3) float array in [0, 1], gamma-encoded sRGB
        (e.g. :func:`albedo_model.io.image_io.read_image`).
    bins : int
        Histogram bins per channel (25 in the reference).
    smooth_sigma : float, optional
        Convolve the histogram with the pixel noise ``N(0, smooth_sigma^2)``
        (:meth:`ColourHistogram.smoothed_log_density`; pass the pixel model's
        sigma). None keeps the raw piecewise-constant histogram (the reference).
    colour : {"linear", "srgb"}
        The comparison space: ``"linear"`` linearises the photograph (``x^2.2``);
        ``"srgb"`` keeps its encoded values (clipped to [0, 1]), for a model
        whose colour is an sRGB texture.
    sensor_sigma : float
        Sd of the photograph's noise in its encoded values: the linearisation
        takes off the bias that noise gives it (:func:`linearise`; ``"linear"`` only).

    Raises
    ------
    InputError
        Wrong shape, non-finite values or an unknown ``colour``.
    """
    img = np.asarray(image, np.float64)
    if img.ndim != 3 or img.shape[2] != 3 or min(img.shape[:2]) < 1:
        raise InputError(f"target image must have shape (H, W, 3), got {img.shape}")
    if not np.all(np.isfinite(img)):
        raise InputError("target image contains NaN or infinite values")
    if colour not in ("linear", "srgb"):
        raise InputError(f"image colour space must be 'linear' or 'srgb', got {colour!r}")
    lin = linearise(img, sensor_sigma) if colour == "linear" else np.clip(img, 0.0, 1.0)
    hist = colour_histogram(lin, bins=bins)
    bg = hist.log_density(lin) if smooth_sigma is None else \
        hist.smoothed_log_density(lin, float(smooth_sigma))
    arrays = ImageArrays(
        rgb=tuple(jnp.asarray(lin[..., c], jnp.float32) for c in range(3)),
        bg=jnp.asarray(bg, jnp.float32),
    )
    return ImageTarget(lin, hist, arrays, colour)


_DEVICE_FUNCTIONS = {"independent": independent_terms, "collective": collective_terms,
                     "trimmed": trimmed_terms, "region": region_terms,
                     "robust": robust_region_terms}


def _on_pixel_set(terms):
    """Wrap ``terms`` to take the pixel set as third argument.

    That is how ``Renderer.compose(pixel_set=True)`` calls it.
    """
    def on_set(rgb, mask, pixels, *args):
        return terms(rgb, mask, *args, pixels=pixels)
    on_set.__name__ = f"{terms.__name__}_on_pixel_set"
    return on_set


# one function object per kind, so that compiled programs are shared across fits
_PIXEL_SET_FUNCTIONS = {k: _on_pixel_set(f) for k, f in _DEVICE_FUNCTIONS.items()}


@functools.cache
def _jitted(kind: str):
    return jax.jit(_DEVICE_FUNCTIONS[kind])


@dataclass(frozen=True, eq=False)
class ImageLikelihood:
    """An image likelihood bound to a target: ``log_lik(shaded) -> float``.

    Parameters
    ----------
    target : ImageTarget
    kind : {"independent", "collective", "trimmed"}
        Independent Gaussian pixels against the histogram background (the
        reference's fit), the collective CLT likelihood, or the independent one
        over the best ``trim_fraction`` of the face pixels.
    sigma : float
        Per-channel colour noise (linear units) of the Gaussian pixel model; the
        collective likelihood uses ``sqrt(3) sigma`` as its RMS distance.
    trim_fraction : float in (0, 1]
    relative_variance : float
        Of the collective likelihood (2/3: Gaussian per-channel noise).
    temperature : float
        The log likelihood is divided by it (1: the plain likelihood). Pixels
        are not independent (model errors are smooth over the face), so the
        plain product is overconfident; T > 1 counts about N / T effective pixels.
    region : (H W,) bool array, optional
        A fixed set of pixels (e.g. :func:`albedo_model.render.region.interior_region`
        at a fit's mode). Then the likelihood is the Gaussian of ``sigma`` over
        exactly these pixels, hit or not (a miss has the ``background``
        colour), and no background density enters: a smooth function of the
        scene, where the other kinds sum over the pixels the render covers and
        jump whenever a silhouette pixel flips. ``kind`` must be "independent".
    background : (3,) float
        The renderer's colour of pixels without a hit (with ``region``).
    outlier_probability : float in [0, 1), or (H W,) float array
        With ``region``: the prior probability ``eps`` that a pixel shows
        something the face model cannot explain (hair, glasses, a hand), one
        for all pixels or one each. Each region pixel then scores
        ``log((1 - eps) N(I; R, sigma^2) + eps h(I))``
        (:func:`~mcmcfit.targets.robust_foreground.robust_region_terms`, ``h``
        the background density); 0 is the plain Gaussian.
    occluder : (H W,) float array, optional
        The robust foreground's occluder log density ``log h(I)`` per pixel
        (:func:`~mcmcfit.targets.background.occluder_log_density`); default: the
        target's background density.
    """

    target: ImageTarget
    kind: str = "independent"
    sigma: float = 0.043
    trim_fraction: float = 0.9
    relative_variance: float = 2.0 / 3.0
    temperature: float = 1.0
    region: np.ndarray | None = None
    background: tuple = (0.0, 0.0, 0.0)
    outlier_probability: float | np.ndarray = 0.0
    occluder: np.ndarray | None = None
    _fn: object = field(init=False, repr=False)
    _args: tuple = field(init=False, repr=False)
    _region_constants: tuple = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Validate the settings and prepare the jitted terms and their device arguments."""
        if self.kind not in IMAGE_LIKELIHOODS:
            raise InputError(f"image likelihood must be one of {IMAGE_LIKELIHOODS}, "
                             f"got {self.kind!r}")
        if not (math.isfinite(self.sigma) and self.sigma > 0):
            raise InputError(f"pixel sigma must be > 0, got {self.sigma!r}")
        if not 0.0 < self.trim_fraction <= 1.0:
            raise InputError(f"trim fraction must be in (0, 1], got {self.trim_fraction!r}")
        if not (math.isfinite(self.temperature) and self.temperature >= 1.0):
            raise InputError(f"likelihood temperature must be >= 1, got {self.temperature!r}")
        eps = np.asarray(self.outlier_probability, np.float64)
        if eps.ndim not in (0, 1) or (eps.ndim == 1 and eps.size != self.target.height
                                      * self.target.width):
            raise InputError("outlier probability must be a number or one per image pixel, "
                             f"got shape {eps.shape}")
        if not np.all((eps >= 0.0) & (eps < 1.0)):
            raise InputError("outlier probability must be in [0, 1), "
                             f"got values in [{eps.min()}, {eps.max()}]")
        if self.robust and self.region is None:
            raise InputError("a robust foreground (outlier probability > 0) needs a fixed "
                             "pixel region (the Gaussian sampler)")
        object.__setattr__(self, "_fn", _jitted(self.device_kind))
        # one device scalar for every call (a fresh jnp.float32 per step is a host->device copy)
        args = (self.target.arrays,) if self.kind == "collective" else (
            self.target.arrays, jnp.float32(self.sigma))
        constants = (0, np.zeros(0, np.int64), np.zeros(0))
        if self.region is not None:
            if self.kind != "independent":
                raise InputError("a fixed pixel region needs the independent (Gaussian) "
                                 f"likelihood, got {self.kind!r}")
            h, w = self.target.height, self.target.width
            region = np.asarray(self.region, bool).reshape(-1)
            if region.shape[0] != h * w:
                raise InputError(f"pixel region has {region.shape[0]} pixels, the image {h * w}")
            lin = self.target.linear.reshape(-1, 3).astype(np.float32).astype(np.float64)
            s32 = float(np.float32(self.sigma))
            miss = -np.sum((lin - np.asarray(self.background, np.float64)) ** 2, axis=1) * (
                0.5 / (s32 * s32))
            args = args + (jnp.asarray(region.reshape(h, w)),)
            if self.robust:
                face_log, out_log = self.robust_logs()
                miss = np.logaddexp(face_log + miss, out_log)
                args = args + tuple(jnp.asarray(a.reshape(h, w), jnp.float32)
                                    for a in (face_log, out_log))
            index = np.flatnonzero(region)
            constants = (int(index.size), index, miss[index])
        object.__setattr__(self, "_args", args)
        object.__setattr__(self, "_region_constants", constants)

    @property
    def device_kind(self) -> str:
        """The device terms evaluated: ``kind``, or ``"region"`` with a fixed region."""
        if self.region is None:
            return self.kind
        return "robust" if self.robust else "region"

    @property
    def robust(self) -> bool:
        """Whether the foreground is robust (some pixel's outlier probability above 0)."""
        return bool(np.any(np.asarray(self.outlier_probability) > 0.0))

    def robust_logs(self, pixels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Return the robust foreground's ``(face_log, out_log)`` at ``pixels`` (row-major; default all).

        See :func:`~mcmcfit.targets.robust_foreground.robust_logs`; float64, host,
        with the float32 sigma the device uses.
        """
        bg = np.asarray(self.target.arrays.bg if self.occluder is None else self.occluder,
                        np.float64).reshape(-1)
        eps = np.broadcast_to(np.asarray(self.outlier_probability, np.float64), bg.shape)
        if pixels is not None:
            bg, eps = bg[pixels], eps[pixels]
        return robust_logs(float(np.float32(self.sigma)), eps, bg)

    @property
    def n_region(self) -> int:
        """Pixels of the fixed region (0 without one)."""
        return self._region_constants[0]

    @property
    def device_fn(self):
        """The pure JAX function ``fn(rgb, mask, *device_args())`` of this kind.

        Suitable for fusing into the shading ``jit``
        (:meth:`albedo_model.render.renderer.Renderer.compose`); :meth:`finish` turns its
        result into the log likelihood.
        """
        return _DEVICE_FUNCTIONS[self.device_kind]

    @property
    def pixel_set_fn(self):
        """:attr:`device_fn` on a renderer's pixel set: ``fn(rgb, mask, pixels, *device_args())``.

        For :meth:`albedo_model.render.renderer.Renderer.compose` with ``pixel_set=True``:
        the per-pixel work follows the face's size, not the image's.
        """
        return _PIXEL_SET_FUNCTIONS[self.device_kind]

    def device_args(self) -> tuple:
        """Return the arguments after ``(rgb, mask)`` of :attr:`device_fn`."""
        return self._args

    def terms(self, rgb, mask):
        """Device partial results for the shader output (see :mod:`mcmcfit.targets.likelihoods`)."""
        return self._fn(rgb, mask, *self.device_args())

    def finish(self, rows, counts, prim_id=None) -> float:
        """Host float64 value from the device results (partial sums, or values and mask).

        With a fixed region, ``prim_id`` (the ray cast's (H W,) triangle ids) tells
        which region pixels the render missed; their constant terms are added here.
        """
        rows, counts = np.asarray(rows), np.asarray(counts)
        if self.region is not None:
            if prim_id is None:
                raise InputError("a region likelihood needs the ray cast's triangle ids")
            n_region, index, miss = self._region_constants
            missed = np.asarray(prim_id)[index] < 0
            miss_total = float(np.sum(miss[missed]))
            value = (miss_total + float(np.sum(np.asarray(rows, np.float64)))
                     if self.robust else
                     finish_region(rows, n_region, miss_total, self.sigma))
        elif self.kind == "independent":
            value = finish_independent(rows, counts, self.sigma)
        elif self.kind == "collective":
            value = finish_collective(rows, counts, math.sqrt(3.0) * self.sigma,
                                      self.relative_variance)
        else:
            value = finish_trimmed(rows, counts, self.sigma, self.trim_fraction)
        return value if self.temperature == 1.0 else value / self.temperature

    def __call__(self, shaded: Shaded) -> float:
        """Log likelihood of the target given a render (linear colours, full-image arrays)."""
        prim = None if self.region is None else np.where(np.asarray(shaded.mask), 0, -1)
        return self.finish(*self.terms(shaded.rgb, shaded.mask), prim_id=prim)
