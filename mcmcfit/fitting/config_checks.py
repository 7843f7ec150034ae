"""Validation of a :class:`~mcmcfit.fitting.config.FitConfig`: every setting's type and range.

This module imports :mod:`albedo_model.errors` and :mod:`mcmcfit.targets.image` (for
the likelihood names).
"""

from __future__ import annotations

import math

from albedo_model.errors import InputError
from mcmcfit.targets.image import IMAGE_LIKELIHOODS

__all__ = ["check_config"]


def check_config(cfg) -> None:
    """Raise InputError naming the first invalid setting of ``cfg`` (a FitConfig)."""
    def count(name: str, minimum: int = 0) -> None:
        v = getattr(cfg, name)
        if not isinstance(v, int) or isinstance(v, bool) or v < minimum:
            raise InputError(f"fit config: {name} must be an integer >= {minimum}, got {v!r}")

    for name in ("steps", "landmark_steps", "n_shape", "n_albedo", "n_expression"):
        count(name)
    count("noise_updates")
    count("widen_at")
    count("hmc_leapfrog", 1)
    for name in ("mode_rounds", "mode_steps", "region_erode", "region_band"):
        count(name)
    if cfg.warmup_steps is not None:
        count("warmup_steps")
    for name in ("chains", "shadow_rays", "thin", "bins", "solver_points", "albedo_points", "adapt_window",
                 "check_every"):
        count(name, 1)
    count("emcee_walkers", 2 * 8 + 2)
    for name in ("sigma_px", "sigma_lm", "solver_sigma", "mala_step", "face_box_scale_sigma",
                 "face_box_centre_sigma"):
        v = getattr(cfg, name)
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"fit config: {name} must be > 0, got {v!r}")
    for name in ("stage1_shape_weight", "specular_weight", "albedo_weight",
                 "light_conditional_weight", "mala_weight", "pcn_weight", "block_weight", "hmc_weight",
                 "conditional_weight"):
        v = getattr(cfg, name)
        if not (math.isfinite(v) and v >= 0):
            raise InputError(f"fit config: {name} must be >= 0, got {v!r}")
    choices = {"likelihood": IMAGE_LIKELIHOODS, "stage1": ("mh", "emcee"),
               "background": ("smoothed", "histogram"),
               "init_pose": ("lsq", "similarity"), "init_light": ("solve", "frontal"),
               "noise": ("estimated", "fixed"), "sampler": ("gaussian", "reference", "random-walk"),
               "hmc_triangles": ("cast", "mode"), "metric": ("gauss-newton", "hessian", "fisher"),
               "effects": ("auto", "sh", "sh+directional"),
               "foreground": ("gaussian", "robust")}
    for name, allowed in choices.items():
        if getattr(cfg, name) not in allowed:
            raise InputError(f"fit config: {name} must be one of {allowed}, "
                             f"got {getattr(cfg, name)!r}")
    if not 0.0 < cfg.lm_hidden_probability <= 1.0:
        raise InputError("fit config: lm_hidden_probability must be in (0, 1], "
                         f"got {cfg.lm_hidden_probability}")
    if not 0.0 < cfg.trim_fraction <= 1.0:
        raise InputError(f"fit config: trim_fraction must be in (0, 1], got {cfg.trim_fraction}")
    if not (isinstance(cfg.temperature, (int, float)) and math.isfinite(cfg.temperature)
            and cfg.temperature >= 1.0):
        raise InputError(f"fit config: temperature must be >= 1, got {cfg.temperature!r}")
    if not 0.0 <= cfg.burn_fraction < 1.0:
        raise InputError(f"fit config: burn_fraction must be in [0, 1), got {cfg.burn_fraction}")
    if cfg.block_size is not None and cfg.block_size < 1:
        raise InputError(f"fit config: block_size must be >= 1 or None, got {cfg.block_size}")
    if cfg.time_budget is not None and not (
            isinstance(cfg.time_budget, (int, float)) and cfg.time_budget > 0):
        raise InputError(f"fit config: time_budget must be > 0 seconds or None, "
                         f"got {cfg.time_budget!r}")
    if cfg.model_colour not in (None, "linear", "srgb"):
        raise InputError("fit config: model_colour must be 'linear', 'srgb' or None "
                         f"(read from the model), got {cfg.model_colour!r}")
    if cfg.threads not in (None, 1, 2):
        raise InputError(f"fit config: threads must be 1, 2 or None, got {cfg.threads}")
    if not (isinstance(cfg.shadow_spread_deg, (int, float))
            and 0.0 <= cfg.shadow_spread_deg < 45.0):
        raise InputError("fit config: shadow_spread_deg must be in [0, 45) degrees, "
                         f"got {cfg.shadow_spread_deg!r}")
    if not 0.0 < cfg.outlier_probability < 0.5:
        raise InputError("fit config: outlier_probability must be in (0, 0.5), "
                         f"got {cfg.outlier_probability!r}")
    if cfg.foreground == "robust" and cfg.sampler != "gaussian":
        raise InputError("fit config: foreground 'robust' needs the gaussian sampler (its "
                         "fixed pixel region)")
    if cfg.effects == "sh+directional" and cfg.sampler != "gaussian":
        raise InputError("fit config: effects 'sh+directional' needs the gaussian sampler")
