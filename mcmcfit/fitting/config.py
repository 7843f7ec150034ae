"""Settings of one fit, as a frozen dataclass saved as JSON beside the results.

This module imports :mod:`albedo_model.errors`, :mod:`mcmcfit.targets.priors` and
:mod:`mcmcfit.targets.image` (for the likelihood names).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field

from albedo_model.errors import InputError
from mcmcfit.targets.image import IMAGE_LIKELIHOODS
from mcmcfit.targets.priors import PriorConfig

__all__ = ["FitConfig"]


@dataclass(frozen=True)
class FitConfig:
    """Everything that controls a fit except the data and the seed.

    Attributes
    ----------
    steps : int
        Image-stage (stage 2) steps per chain (reference: 10000); 0 skips stage 2.
    landmark_steps : int
        Landmark-stage (stage 1) steps per chain (reference: 5000); with
        ``stage1="emcee"`` the number of log-density evaluations (iterations x
        walkers). 0 skips stage 1 (the pose guess is the start of stage 2).
    chains : int
        Independent chains, run one after the other (seeds from ``SeedSequence.spawn``).
        Default 1: the budget is 90 s per fit at 250² on a 2-core machine, and one
        chain of the default schedule (5000 landmark + 10000 image steps) took
        88 s there (stage 2 at ~120 steps/s, measured with other jobs running;
        ``mcmcfit bench fit``). Two chains would take twice that: the ray caster
        already uses both cores, so chains in parallel threads gain little.
        Convergence is still checked with one chain: R-hat is split R-hat (the
        chain's halves). Use ``chains=2`` or more for cross-chain R-hat.
    thin : int
        Keep every ``thin``-th state as a sample (per-step logs are kept in full).
    sigma_px : float
        Per-channel colour noise of the pixel model, linear units (reference 0.043).
    sigma_lm : float
        Landmark noise in pixels (reference 4.0).
    lm_hidden_probability : float in (0, 1]
        Probability that a landmark hidden in the model is clicked as visible
        (see :mod:`mcmcfit.targets.landmarks`).
    bins : int
        Background histogram bins per channel (reference 25).
    background : {"smoothed", "histogram"}
        Background density of the independent (and trimmed) image likelihood:
        the colour histogram convolved with the pixel noise ``N(0, sigma_px^2)``
        (default; a density of the same noisy colour as the foreground Gaussian,
        never above its peak, so faces are not rewarded for shrinking), or the
        raw piecewise-constant histogram (the reference's).
    likelihood : {"independent", "collective", "trimmed"}
    trim_fraction : float
        Fraction of face pixels kept by the trimmed likelihood.
    temperature : float >= 1
        The image log likelihood is divided by it (a tempered, "power" likelihood
        counting about N / T effective pixels). Model errors are smooth over the
        face, so its pixels are far from independent, and the plain product
        (T = 1, the reference's) gives albedo intervals that cover the truth far
        too rarely (7-20 % of the 90 % intervals on synthetic faces of the default
        model, against 73-95 % with T = 40 at 3000 steps, where the RMSE was no
        worse); the tempered chain also accepts more and mixes faster.
    specular : bool
        Render the specular term (when the model has specular albedo).
    stage1 : {"mh", "emcee"}
        Sampler of the landmark stage.
    emcee_walkers : int
    stage1_shape_weight : float
        Weight of shape moves in the landmark stage (0: pose and camera only, as the
        reference). Default 0.5: with the shape fixed at the mean, the landmark
        residuals of a non-mean face bias the pose (median error 5.4 deg on five
        synthetic faces of the default model, 1.9 deg with shape moves).
    n_shape, n_albedo, n_expression : int
        Coefficients sampled (clipped to the model's ranks; reference 50 / 50 / 5).
    block_size : int or None
        Coefficients moved per random-walk step (None: all, as the reference).
    init_pose : {"lsq", "similarity"}
        Pose guess: frontal similarity, refined by perspective least squares ("lsq") or not.
    init_light : {"solve", "frontal"}
        Start of stage 2's light: least-squares SH solve at the landmark fit, or SH frontal.
    solver_points : int
        Pixels used by the SH light solver proposal.
    solver_sigma : float
        Spread of the solver proposal around the least-squares light.
    specular_weight : float
        Top-level weight of the specular-exponent proposal (0 turns it off).
    albedo_weight : float
        Top-level weight of the albedo conditional proposal (a Gibbs-like draw of
        all albedo coefficients from their Gaussian conditional; 0 turns it off).
    albedo_points : int
        Face pixels the albedo conditional reads (a fixed random subset, each
        standing for face pixels / albedo_points of them). Fewer are cheaper
        but a poorer match of the conditional; with the tempered likelihood
        (``temperature``) 4000 of ~18000 still match well.
    burn_fraction : float
        Leading fraction of stage 2 dropped for the mean parameters and diagnostics.
    face_box_scale_sigma, face_box_centre_sigma : float
        Face-box likelihood scales (log scale; fraction of the box diagonal).
    threads : int or None
        Ray-casting threads (1 or 2; None: min(2, CPUs)).
    check_cache : bool
        Debug mode (``--check-cache``): after every step compare every cached
        product (render, log densities, proposal data) with a fresh computation
        (:mod:`mcmcfit.fitting.cache_check`); several times slower.
    prior : PriorConfig
    """

    steps: int = 10000
    landmark_steps: int = 5000
    chains: int = 1
    thin: int = 10
    sigma_px: float = 0.043
    sigma_lm: float = 4.0
    lm_hidden_probability: float = 0.05
    bins: int = 25
    background: str = "smoothed"
    likelihood: str = "independent"
    trim_fraction: float = 0.9
    temperature: float = 40.0
    specular: bool = True
    stage1: str = "mh"
    emcee_walkers: int = 32
    stage1_shape_weight: float = 0.5
    n_shape: int = 50
    n_albedo: int = 50
    n_expression: int = 5
    block_size: int | None = 10
    init_pose: str = "lsq"
    init_light: str = "solve"
    solver_points: int = 200
    solver_sigma: float = 0.005
    specular_weight: float = 0.1
    albedo_weight: float = 0.25
    albedo_points: int = 4000
    burn_fraction: float = 0.25
    face_box_scale_sigma: float = 0.1
    face_box_centre_sigma: float = 0.1
    threads: int | None = None
    check_cache: bool = False
    prior: PriorConfig = field(default_factory=PriorConfig)

    def __post_init__(self) -> None:
        """Validate every setting; an invalid one raises InputError."""
        def count(name: str, minimum: int = 0) -> None:
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < minimum:
                raise InputError(f"fit config: {name} must be an integer >= {minimum}, got {v!r}")

        for name in ("steps", "landmark_steps", "n_shape", "n_albedo", "n_expression"):
            count(name)
        for name in ("chains", "thin", "bins", "solver_points", "albedo_points"):
            count(name, 1)
        count("emcee_walkers", 2 * 8 + 2)
        for name in ("sigma_px", "sigma_lm", "solver_sigma", "face_box_scale_sigma",
                     "face_box_centre_sigma"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"fit config: {name} must be > 0, got {v!r}")
        for name in ("stage1_shape_weight", "specular_weight", "albedo_weight"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"fit config: {name} must be >= 0, got {v!r}")
        choices = {"likelihood": IMAGE_LIKELIHOODS, "stage1": ("mh", "emcee"),
                   "background": ("smoothed", "histogram"),
                   "init_pose": ("lsq", "similarity"), "init_light": ("solve", "frontal")}
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise InputError(f"fit config: {name} must be one of {allowed}, "
                                 f"got {getattr(self, name)!r}")
        if not 0.0 < self.lm_hidden_probability <= 1.0:
            raise InputError("fit config: lm_hidden_probability must be in (0, 1], "
                             f"got {self.lm_hidden_probability}")
        if not 0.0 < self.trim_fraction <= 1.0:
            raise InputError(f"fit config: trim_fraction must be in (0, 1], got {self.trim_fraction}")
        if not (isinstance(self.temperature, (int, float)) and math.isfinite(self.temperature)
                and self.temperature >= 1.0):
            raise InputError(f"fit config: temperature must be >= 1, got {self.temperature!r}")
        if not 0.0 <= self.burn_fraction < 1.0:
            raise InputError(f"fit config: burn_fraction must be in [0, 1), got {self.burn_fraction}")
        if self.block_size is not None and self.block_size < 1:
            raise InputError(f"fit config: block_size must be >= 1 or None, got {self.block_size}")
        if self.threads not in (None, 1, 2):
            raise InputError(f"fit config: threads must be 1, 2 or None, got {self.threads}")

    def to_dict(self) -> dict:
        """Plain JSON-able dict (``prior`` nested)."""
        return dataclasses.asdict(self)

    def to_json(self) -> str:
        """Stable JSON text (sorted keys)."""
        return json.dumps(self.to_dict(), sort_keys=True, indent=2)

    @classmethod
    def from_dict(cls, data: dict) -> FitConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        data = dict(data)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise InputError(f"fit config: unknown setting {unknown[0]!r}")
        prior = data.pop("prior", None)
        if isinstance(prior, dict):
            pk = {f.name for f in dataclasses.fields(PriorConfig)}
            bad = sorted(set(prior) - pk)
            if bad:
                raise InputError(f"fit config: unknown prior setting {bad[0]!r}")
            if "light_band_sigma" in prior:
                prior["light_band_sigma"] = tuple(prior["light_band_sigma"])
            data["prior"] = PriorConfig(**prior)
        elif prior is not None:
            data["prior"] = prior
        return cls(**data)

    @classmethod
    def from_json(cls, text: str) -> FitConfig:
        """Read a config from JSON text (as :meth:`to_json` writes it), validated."""
        return cls.from_dict(json.loads(text))

    def replace(self, **changes) -> FitConfig:
        """Return a copy with some settings changed (validated)."""
        return dataclasses.replace(self, **changes)
