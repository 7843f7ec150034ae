"""Settings of one fit, as a frozen dataclass saved as JSON beside the results.

This module imports :mod:`albedo_model.errors`, :mod:`mcmcfit.targets.priors` and
:mod:`mcmcfit.fitting.config_checks` (the validation).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field

from albedo_model.errors import InputError
from mcmcfit.fitting.config_checks import check_config
from mcmcfit.targets.priors import PriorConfig

__all__ = ["GAUSSIAN_WARMUP", "FitConfig"]

#: Default warm-up steps per chain of the Gaussian sampler (its chains start in the bulk,
#: from a draw of the Laplace approximation: the warm-up only adapts the step sizes). On
#: the demo face 500 steps converged as fast as 1000 did and saved ~20 s.
GAUSSIAN_WARMUP = 500


@dataclass(frozen=True)
class FitConfig:
    """Everything that controls a fit except the data and the seed.

    Attributes
    ----------
    sampler : {"gaussian", "reference", "random-walk"}
        The image stage. ``"gaussian"`` (default): every chain climbs to the
        posterior mode (Levenberg-Marquardt through the JAX pixel Jacobian,
        :mod:`mcmcfit.fitting.mode`), the image likelihood is then fixed to the
        interior pixels of the face there (:func:`albedo_model.render.region.interior_region`)
        with its noise measured there, and the chains sample with moves from the
        posterior's Laplace approximation (Crank-Nicolson on every coordinate
        and on blocks, :mod:`proposals.laplace.moves`) and the albedo's and light's
        exact conditionals. ``"reference"``: the same preparation and posterior,
        sampled with the random-walk schedule (:func:`proposals.schedule.default_image_proposal`;
        with the reference's settings in ``mcmcfit bench fit``). ``"random-walk"``:
        the previous default, the random walks and conditionals on the likelihood
        over the pixels the render covers, with a random-walk warm-up.
    steps : int
        Most kept image-stage steps per chain (``--max-steps``; reference: 10000
        image steps); the stage ends earlier when the chains have converged
        (``stop_when_converged``). 0 skips the image stage.
    landmark_steps : int
        Landmark-stage (stage 1) steps per chain (reference: 5000); with
        ``stage1="emcee"`` the number of log-density evaluations (iterations x
        walkers). 0 skips stage 1 (the pose guess is the start of stage 2).
    chains : int
        Independent chains (seeds from ``SeedSequence.spawn``). Default 2, one
        per core of a 2-core machine: cross-chain R-hat needs several chains.
    parallel : bool
        Run the chains in parallel worker processes (one ray-casting thread
        each; :mod:`mcmcfit.fitting.chain_pool`); False runs them one after the
        other in this process (the same chains, only slower).
    warmup_steps : int or None
        Image-stage warm-up steps per chain (step sizes adapted; never kept).
        None: :data:`GAUSSIAN_WARMUP` (500) for the Gaussian sampler (after its
        climb; its chains start from a draw of the Laplace approximation), 30 %
        of ``steps`` for the random-walk one (which measures the noise model in
        it; with 0 the configured noise model is kept).
    adapt_window : int
        Warm-up steps between two step-size adaptations.
    adapt : bool
        Adapt the step sizes during warm-up (False: the reference's fixed scales).
    check_every : int
        Kept steps per chain between two convergence checks.
    mode_rounds : int
        Gaussian sampler: climbs to the mode, each with the pixel region and the
        noise model re-chosen at the point the last one reached.
    mode_steps : int
        Gaussian sampler: most Levenberg-Marquardt steps per climb (it ends once
        a step gains < 0.1 in log density; a poor landmark fit can need 20+).
    region_erode, region_band : int
        Gaussian sampler: pixels the region keeps away from the face's
        silhouette and from occlusion contours.
    pcn_weight, block_weight, conditional_weight : float
        Gaussian sampler: top-level weights of the Crank-Nicolson moves of every
        coordinate, of the Gaussian block moves (geometry, albedo, shading:
        :data:`proposals.laplace.schedule.BLOCK_SHARES`) and of the albedo's and the
        SH light's exact conditionals (half each).
    hmc_weight, hmc_leapfrog, hmc_random_steps : float, int, bool
        Gaussian sampler: top-level weight of the whitened HMC move of every
        coordinate (:class:`proposals.laplace.moves.GaussianHMC`; each of its
        ``hmc_leapfrog`` leapfrog steps is a ray cast and a gradient through the
        shading), 0 for none. Default 3 steps: at the adapted step (~0.45 in
        whitened units) a trajectory turns ~1.4 rad in a unit-variance direction,
        near the quarter period that decorrelates a coordinate and its square;
        6 steps turn ~2.9 rad, nearly a half period, which leaves the square
        (what the folded R-hat and the tail-ESS read) almost unchanged. With
        ``hmc_random_steps`` each move draws its number of steps uniformly
        from 1 to ``2 hmc_leapfrog - 1`` (same mean cost, no fixed period).
    hmc_triangles : {"cast", "mode"}
        Gaussian sampler: the triangles the HMC gradient renders each region
        pixel with: those a ray cast at the point sees (``"cast"``: the exact
        gradient) or those of the mode, each triangle's plane extrapolated
        (``"mode"``: a smooth surrogate, no ray cast per leapfrog step). Either
        is a function of the position alone, so the move stays exact; the
        acceptance test uses the exact ray-cast posterior.
    image_size : bool
        Gaussian sampler: sample the log image size of the face in place of
        the log focal length (:mod:`proposals.laplace.image_scale`; the
        anchors are the vertices the region sees at the mode). Straightens the
        curved focal-length/distance/size ridge the Laplace approximation
        cannot follow. Perspective cameras only (ignored for orthographic ones).
    inverse_distance : bool
        Gaussian sampler (with ``image_size``): sample ``d_0 / d`` in place of
        the log distance (:class:`proposals.laplace.coordinates.SamplingCoordinates`):
        the perspective's ridge with the shape and pose is straight in it.
    metric : {"gauss-newton", "hessian", "fisher"}
        Gaussian sampler: the approximation the moves whiten with: the climb's Laplace
        approximation (``"gauss-newton"``), widened where the Hessian by central differences
        of the exact gradient is flatter (``"hessian"``, did not mix better, README;
        :mod:`mcmcfit.fitting.curvature_widening`), or (the default, ``"fisher"``) at 60 % of
        the warm-up where 150 draws per chain and the gradients at them say it is wider
        (:func:`proposals.laplace.widening.widened_by_fisher`).
    recentre : bool
        Gaussian sampler: after each warm-up window, a chain whose best draw
        beats its mode by more than 10 nats climbs again from that draw, and the
        Laplace approximation and the moves are rebuilt at the new mode (a climb
        can stop short on a long ridge); a re-centring in the last window adds
        one more window of warm-up (at most 3 re-centrings; only with ``adapt``;
        :meth:`~mcmcfit.fitting.draw_phases.DrawPhases.recentre`).
    widen : bool
        Gaussian sampler: at 60 % of the warm-up, widen the Laplace
        approximation the moves whiten with along the (at most 4) directions
        where the chains' warm-up draws are clearly wider
        (:func:`proposals.laplace.widening.widened_by_draws`; the rest of the
        warm-up re-adapts the step sizes, the kept draws see it frozen).
    widen_at : int
        Gaussian sampler: at the first convergence check with at least this
        many kept steps that has not passed, widen the approximation where the
        kept draws of all chains are clearly wider; if any direction is
        widened, those draws become warm-up, the step sizes are re-adapted for
        100 steps and the kept draws start again (0: never).
    albedo_offsets : bool
        Gaussian sampler: the albedo's exact conditional draws the colour
        transform's offsets with the albedo coefficients
        (:class:`proposals.albedo_offset.AlbedoOffsetConditional`; False: the
        albedo alone).
    contrast_light : bool
        Gaussian sampler, single fits: a colour-contrast step with the SH light
        redrawn under it (:class:`proposals.light_conditional.ContrastLightExchange`; README).
    stop_when_converged : bool
        End the image stage at the first check where every monitored quantity
        has rank-normalised split R-hat < 1.01 and bulk- and tail-ESS >= 400.
    time_budget : float or None
        Seconds (from the start of the fit) after which no further round of
        kept draws is started (``--time-budget``); None: no limit.
    noise : {"estimated", "fixed"}
        The image likelihood's scale: measured per image from the residuals at
        the end of the first warm-up phase (RMS residual as sigma, their
        correlation area as the temperature; :mod:`mcmcfit.targets.noise_model`),
        or ``sigma_px`` and ``temperature`` as given. The configured values are
        the provisional model of the first warm-up phase either way.
    noise_updates : int
        With ``noise="estimated"``: how many times the scale is measured
        during warm-up (at equal intervals; each time at the best state since
        the last change, so that it follows the fit as it improves).
    thin : int
        Keep every ``thin``-th state as a sample (per-step logs are kept in
        full). Default 1: the Gaussian sampler's steps are nearly independent,
        and the ESS of a parameter cannot exceed its number of kept samples.
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
        With ``noise="fixed"``: the image log likelihood is divided by it (a
        tempered likelihood counting about N / T effective pixels). Otherwise it
        is only the provisional value of the first warm-up phase (broad, so the
        chains move fast before the scale is measured).
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
    light_conditional_weight : float
        Top-level weight of the SH light's exact conditional draw (over all
        face pixels; replaces the least-squares solver proposal; 0 turns it off
        and restores the solver).
    mala_weight : float
        Top-level weight of the gradient move (preconditioned MALA on shape,
        expression, pose and focal length together; :mod:`proposals.gradient`).
        Default 0 (off): measured on the demo case it did not improve the
        chains' R-hat or ESS per second (a diagonal preconditioner misses the
        strong shape-pose correlations, and a gradient costs 2-4 render steps
        plus ~8 s of compilation per process); try 0.5.
    mala_step : float
        Its initial step size (adapted in warm-up towards 57 % acceptance; the
        preconditioner is set from the warm-up draws).
    albedo_points : int
        Face pixels the albedo conditional reads at most (a fixed random subset
        beyond that, each standing for face pixels / albedo_points of them).
        Default: all of them, so that the draw is the exact conditional.
    burn_fraction : float
        Leading fraction of the kept draws dropped as well (default 0: the
        warm-up is separate).
    face_box_scale_sigma, face_box_centre_sigma : float
        Face-box likelihood scales (log scale; fraction of the box diagonal).
    threads : int or None
        Ray-casting threads (1 or 2; None: min(2, CPUs)).
    check_cache : bool
        Debug mode (``--check-cache``): after every step compare every cached
        product (render, log densities, proposal data) with a fresh computation
        (:mod:`mcmcfit.fitting.cache_check`); several times slower.
    model_colour : {"linear", "srgb"} or None
        The colour space of the model's colour parts (``--model-colour``); None
        reads it from the model (:func:`albedo_model.io.colour_space.model_colour_space`:
        metadata, then layout). ``"srgb"``: the model's colour is taken as the
        camera's sRGB values, as the reference does, and the render is compared
        with the photograph's encoded values (not linearised); the reported
        albedo is decoded to linear.
    effects : {"auto", "sh", "sh+directional"}
        The light the fit's image model has (``--effects``): the SH light alone,
        or plus one directional light with cast shadows (sampled: direction and
        RGB strength, Gaussian sampler only). ``"auto"`` decides after the first
        climb, from how much a directional light improves the fit of the
        photograph (:mod:`mcmcfit.fitting.effects_choice`); no shadow ray is cast
        unless it is on.
    shadow_rays : int
        Shadow rays per face pixel (``--soft-shadows``): 1 casts hard shadows;
        more sample a light of angular radius ``shadow_spread_deg`` (a soft edge,
        that many times the shadow rays).
    shadow_spread_deg : float
        Angular radius of the directional light for soft shadows (degrees).
    foreground : {"gaussian", "robust"}
        The image likelihood of the Gaussian sampler's pixel region
        (``--foreground``): every pixel the face under Gaussian noise, or each
        pixel the face or, with a probability estimated per photograph (EM at
        the mode, from ``outlier_probability``), something the model cannot
        explain (hair, glasses, a hand; the image's colour density), summed
        out (:func:`mcmcfit.targets.likelihoods.robust_region_terms`).
    outlier_probability : float
        The robust foreground's outlier probability before it is measured (and
        with ``noise="fixed"``).
    prior : PriorConfig
    """

    sampler: str = "gaussian"
    steps: int = 10000
    landmark_steps: int = 5000
    chains: int = 2
    parallel: bool = True
    warmup_steps: int | None = None
    adapt_window: int = 250
    adapt: bool = True
    check_every: int = 250
    mode_rounds: int = 3
    mode_steps: int = 30
    region_erode: int = 2
    region_band: int = 2
    pcn_weight: float = 0.4
    block_weight: float = 0.5
    conditional_weight: float = 0.1
    hmc_weight: float = 0.3
    hmc_leapfrog: int = 3
    hmc_random_steps: bool = False
    contrast_light: bool = True
    hmc_triangles: str = "cast"
    image_size: bool = True
    inverse_distance: bool = False
    metric: str = "fisher"
    recentre: bool = True
    widen: bool = False
    widen_at: int = 0
    albedo_offsets: bool = True
    stop_when_converged: bool = True
    time_budget: float | None = None
    noise: str = "estimated"
    noise_updates: int = 3
    thin: int = 1
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
    light_conditional_weight: float = 0.5
    mala_weight: float = 0.0
    mala_step: float = 0.05
    albedo_points: int = 1_000_000
    burn_fraction: float = 0.0
    face_box_scale_sigma: float = 0.1
    face_box_centre_sigma: float = 0.1
    threads: int | None = None
    check_cache: bool = False
    model_colour: str | None = None
    effects: str = "auto"
    shadow_rays: int = 1
    shadow_spread_deg: float = 3.0
    foreground: str = "gaussian"
    outlier_probability: float = 0.05
    prior: PriorConfig = field(default_factory=PriorConfig)

    def __post_init__(self) -> None:
        """Validate every setting; an invalid one raises InputError."""
        check_config(self)

    @property
    def warmup(self) -> int:
        """Warm-up steps per chain (``warmup_steps``; None: 500 Gaussian, 30 % of ``steps`` random walk)."""
        if self.warmup_steps is not None:
            return self.warmup_steps
        if self.sampler != "random-walk":
            return min(GAUSSIAN_WARMUP, self.steps)
        return (self.steps * 3) // 10

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
