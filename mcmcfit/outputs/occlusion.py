"""Where a robust fit found pixels the face model cannot explain: the occlusion map.

With ``--foreground robust`` each pixel is the face or an occluder (hair,
glasses, a hand), the label summed out of the likelihood
(:func:`mcmcfit.targets.robust_foreground.robust_region_terms`). After the fit,
the same EM the fit measured its noise with
(:func:`mcmcfit.targets.noise_model.robust_noise`: sigma and a smooth occlusion
prior), run on the residual of the posterior-mean scene over its face pixels,
gives each pixel's probability of being an occluder: the occlusion map,
``occlusion.png`` and a count in ``summary.json``. The out-of-span residual scale
(:mod:`mcmcfit.outputs.residual_scale`) leaves those pixels out, so an
occluder does not widen the albedo intervals.

This module imports :mod:`albedo_model` (io.colour_space, render.renderer),
:mod:`mcmcfit.fitting.result`, :mod:`mcmcfit.targets` (background, image, noise_model) and
:mod:`mcmcfit.outputs.figures`.
"""

from __future__ import annotations

import os

import numpy as np

from albedo_model.io.colour_space import model_colour_space
from albedo_model.params import RenderParameter
from albedo_model.render.renderer import Renderer
from mcmcfit.fitting.result import FitResult
from mcmcfit.outputs.figures import save_scalar_map
from mcmcfit.targets.background import occluder_log_density
from mcmcfit.targets.image import prepare_image_target
from mcmcfit.targets.noise_model import robust_noise

__all__ = ["face_probability", "occlusion_record", "save_occlusion_map"]


def face_probability(result: FitResult, renderer: Renderer, params: RenderParameter,
                     image: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Return ``(probability (H, W), face mask (H, W))``: each face pixel's chance of being the face.

    Parameters
    ----------
    result : FitResult
        Its ``noise`` (sigma: the background density's smoothing) and config
        (histogram bins, background smoothing, model colour space).
    renderer : Renderer
        The fit's renderer (its model and image model).
    params : RenderParameter
        The scene to read the residual at (the posterior mean).
    image : (H, W, 3) float
        The photograph as fitted, gamma-encoded in [0, 1].

    Returns
    -------
    tuple or None
        None when the fit's foreground is not robust. Off the face the
        probability is 1.
    """
    noise = dict(result.noise or {})
    if float(noise.get("outlier_probability") or 0.0) <= 0.0:
        return None
    cfg = result.config
    sigma = float(noise["sigma"])
    colour = model_colour_space(renderer.model, cfg.model_colour).value
    target = prepare_image_target(np.asarray(image, np.float64)[..., :3], bins=cfg.bins,
                                  smooth_sigma=sigma if cfg.background == "smoothed" else None,
                                  colour=colour)
    out = renderer.render(params)
    mask = np.asarray(out.mask, bool)
    occluder = occluder_log_density(target.linear, ~mask, bins=cfg.bins,
                                    sigma=sigma if cfg.background == "smoothed" else None)
    _, _, prob = robust_noise(target.linear - np.asarray(out.image, np.float64), occluder, mask)
    return prob, mask


def occlusion_record(prob: np.ndarray, mask: np.ndarray, outlier_probability: float) -> dict:
    """``summary.json``'s ``occlusion``: face pixels, those more likely an occluder, their share."""
    occluded = int(np.count_nonzero(mask & (prob < 0.5)))
    n = int(mask.sum())
    return {"face_pixels": n, "occluded_pixels": occluded,
            "occluded_fraction": occluded / n if n else None,
            "outlier_probability": float(outlier_probability),
            "rule": "a face pixel at the posterior-mean scene is occluded when the robust "
                    "foreground gives it a probability under 0.5 of being the face"}


def save_occlusion_map(path: str | os.PathLike, prob: np.ndarray, mask: np.ndarray) -> None:
    """Write the occluder probability of every face pixel as a picture with a colour bar."""
    save_scalar_map(path, [("pixels the face model cannot explain", 1.0 - prob, mask)], vmax=1.0,
                    label="probability of an occluder\n(robust foreground, posterior mean)",
                    cmap="magma")
