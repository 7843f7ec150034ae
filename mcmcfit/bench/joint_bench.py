"""``mcmcfit bench joint``: time per sampler step of a joint fit of 1, 2, 4 photographs of one face.

One identity of the model (:func:`~mcmcfit.jobs.synthetic_case.synthetic_case`
with one seed) is rendered in several scenes (yaw -25, 30, 0, 15 deg; a side
light in every second one). Each image gets the targets of a fit
(:func:`mcmcfit.fitting.problem.build_posterior`, the configured noise model,
one ray-casting thread) and the random-walk image schedule of a fit
(:func:`proposals.schedule.default_image_proposal` with the SH light's exact
conditional) lifted to it (:class:`proposals.joint.ForImage`); the albedo's
exact conditional is the one over every image
(:class:`proposals.joint.SharedAlbedoConditional`). A step picks an image, then
a move of its schedule: moves of the image's own blocks re-render that image,
moves of the shared shape and albedo re-render every image
(:class:`mcmcfit.targets.joint.JointTarget`).

Reported per number of images: ms per step (median over blocks of steps,
after untimed steps that compile), acceptance, ms per step of the shared and
of the own moves, and the ratio to one image; and one image's plain
:class:`~mcmcfit.targets.face.FaceTarget` with the same schedule (the joint
wrapper's overhead). All in one run, so the ratios hold when the machine's
speed drifts.

This module imports :mod:`albedo_model` (errors, model), :mod:`mcmcfit.fitting`
(config, problem), :mod:`mcmcfit.jobs.synthetic_case`, :mod:`mcmcfit.proposal_data`,
:mod:`mcmcfit.sampling` (kernel, param_vector), :mod:`mcmcfit.targets` (joint,
landmarks) and :mod:`proposals`.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.problem import FitProblem, build_posterior, provisional_noise
from mcmcfit.jobs.synthetic_case import synthetic_case
from mcmcfit.proposal_data.albedo import RenderAlbedoData
from mcmcfit.proposal_data.light import RenderLightData
from mcmcfit.proposal_data.light_system import RenderLightSystem
from mcmcfit.sampling.kernel import init, step
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.targets.joint import JointTarget
from proposals.albedo_solver import AlbedoConditional
from proposals.base import leaves, mixture
from proposals.joint import SHARED, JointParameter, SharedAlbedoConditional, lift
from proposals.light_conditional import LightConditional
from proposals.schedule import CENTERING_LANDMARKS, default_image_proposal

__all__ = ["SCENES", "format_joint_bench", "run_joint_bench"]

#: Per image: yaw (deg) and whether a strong side light shines.
SCENES = ((-25.0, False), (30.0, True), (0.0, False), (15.0, True))
#: Steps per timed block (the median block gives ms per step).
_BLOCK = 50
#: Top-level weight of the albedo's exact conditional per image (beside each image's
#: schedule at weight 1; the fit's random-walk schedule gives its conditional moves 0.25).
_ALBEDO_SHARE = 0.125


def _image_targets(model: MorphableModel, cfg: FitConfig, case, seed: int):
    """One image's posterior and its single-image schedule (as a random-walk fit builds them)."""
    problem = FitProblem(case.image, case.landmarks, None, None, model, cfg, case.truth,
                         ParamLayout.for_params(case.truth))
    post = build_posterior(problem, provisional_noise(cfg), threads=1)
    linear = post.image_target.linear
    geometry = post.geometry
    centring = (geometry.point if all(n in geometry.names for n in CENTERING_LANDMARKS)
                else None)
    mean, sd = post.face.prior.light_gaussian(case.truth.environment_map.coefficients.shape[0])
    light = LightConditional(RenderLightSystem(linear), mean, sd, sigma=post.pixel_sigma)
    albedo = RenderAlbedoData(post.renderer, linear, n_points=cfg.albedo_points, seed=seed)
    schedule = default_image_proposal(
        centring, solver_data=RenderLightData(post.renderer, linear, seed=seed),
        specular_weight=cfg.specular_weight if post.renderer.specular else 0.0,
        block_size=cfg.block_size, pixel_sigma=post.pixel_sigma, light_conditional=light,
        light_conditional_weight=cfg.light_conditional_weight)
    return post, albedo, schedule


def _shared_names(proposal) -> Callable[[str], bool]:
    """Whether the leaf of that name moves a shared block."""
    names = {leaf.name: bool(leaf.touches & SHARED) for _, leaf in leaves(proposal)}
    return lambda name: names.get(name, False)


def _time_steps(target, proposal, start, n_steps: int, warmup: int, seed: int,
                shared_of: Callable[[str], bool]) -> dict:
    """Run every move twice, ``warmup`` steps, then ``n_steps`` timed steps.

    Returns ms per step (the median block of :data:`_BLOCK` steps), acceptance,
    and the mean ms of the steps of shared and of own moves.
    """
    rng = np.random.default_rng(seed)
    state = init(start, target)
    for _, leaf in leaves(proposal):  # every move twice first: no compilation in the timing
        for _ in range(2):
            state, _ = step(rng, state, target, leaf)
    for _ in range(warmup):
        state, _ = step(rng, state, target, proposal)
    blocks, split = [], {True: [0.0, 0], False: [0.0, 0]}
    accepted = 0
    for first in range(0, n_steps, _BLOCK):
        n = min(_BLOCK, n_steps - first)
        t_block = time.perf_counter()
        for _ in range(n):
            t0 = time.perf_counter()
            state, info = step(rng, state, target, proposal)
            kind = split[shared_of(info.proposal)]
            kind[0] += time.perf_counter() - t0
            kind[1] += 1
            accepted += info.accepted
        blocks.append((time.perf_counter() - t_block) / n)
    per = lambda k: 1e3 * split[k][0] / split[k][1] if split[k][1] else float("nan")  # noqa: E731
    return {"ms_per_step": 1e3 * float(np.median(blocks)), "acceptance": accepted / n_steps,
            "ms_shared": per(True), "ms_own": per(False),
            "shared_fraction": split[True][1] / n_steps}


def run_joint_bench(model: MorphableModel, *, images=(1, 2, 4), steps: int = 600,
                    warmup: int = 60, size: int = 250, seed: int = 0,
                    config: FitConfig | None = None,
                    log: Callable[[str], None] | None = None) -> dict:
    """Time joint steps for each number of images (see the module notes).

    Parameters
    ----------
    model : MorphableModel
    images : sequence of int
        Numbers of images, each in 1..4.
    steps, warmup : int
        Timed and untimed steps per configuration.
    size : int
        Image width and height in pixels.
    seed : int
        The identity (``synthetic_case`` seed) and the sampler's seed.
    config : FitConfig, optional
        Settings of the targets and schedule (default ``FitConfig()``; its fixed noise model).
    log : callable, optional
        Progress messages.

    Returns
    -------
    dict
        ``rows`` (per number of images), ``single`` (the plain face target), settings.
    """
    if not images or min(images) < 1 or max(images) > len(SCENES):
        raise InputError(f"numbers of images must be in 1..{len(SCENES)}, got {list(images)}")
    if steps < 1 or warmup < 0:
        raise InputError(f"steps must be >= 1 and warmup >= 0, got {steps}, {warmup}")
    cfg = config or FitConfig()
    say = log or (lambda msg: None)
    cases = [synthetic_case(model, seed=seed, size=size, yaw_deg=yaw, side_light=side)
             for yaw, side in SCENES[:max(images)]]
    rows, plain = [], None
    for n in images:
        say(f"joint bench: {n} image(s)")
        built = [_image_targets(model, cfg, case, seed + i) for i, case in enumerate(cases[:n])]
        target = JointTarget([post.face for post, _, _ in built], built[0][0].face.prior)
        shared = SharedAlbedoConditional([albedo for _, albedo, _ in built],
                                         [post.pixel_sigma for post, _, _ in built])
        lifted = [(1.0, lift(i, schedule)) for i, (_, _, schedule) in enumerate(built)]
        proposal = mixture(*lifted, (_ALBEDO_SHARE * n, shared), name="joint")
        start = JointParameter.share([c.truth for c in cases[:n]])
        rows.append({"images": n, **_time_steps(target, proposal, start, steps, warmup, seed,
                                                _shared_names(proposal))})
        if n == 1:  # the same mixture on the plain face target: the wrapper's cost
            post, albedo, schedule = built[0]
            single = mixture((1.0, schedule), (_ALBEDO_SHARE, AlbedoConditional(
                albedo, sigma=post.pixel_sigma)), name="single")
            plain = _time_steps(post.face, single, cases[0].truth, steps, warmup, seed,
                                _shared_names(single))
    base = rows[0]["ms_per_step"] if rows[0]["images"] == 1 else float("nan")
    for r in rows:
        r["ratio_to_one"] = r["ms_per_step"] / base
    return {"rows": rows, "single": plain, "steps": steps,
            "warmup": warmup, "size": size, "seed": seed}


def format_joint_bench(result: dict) -> str:
    """Format :func:`run_joint_bench`'s result as a table."""
    lines = [f"joint fit, ms per sampler step ({result['steps']} timed steps after "
             f"{result['warmup']}, {result['size']}x{result['size']}, one identity, seed "
             f"{result['seed']})",
             "images  ms/step  x one image  acceptance  shared moves: share, ms  own moves: ms"]
    for r in result["rows"]:
        lines.append(f"{r['images']:>6}  {r['ms_per_step']:7.1f}  {r['ratio_to_one']:11.2f}  "
                     f"{r['acceptance']:10.2f}  {r['shared_fraction']:12.2f}, "
                     f"{r['ms_shared']:5.1f}  {r['ms_own']:13.1f}")
    single = result.get("single")
    if single is not None:
        one = next(r for r in result["rows"] if r["images"] == 1)
        lines.append(f"one image without the joint wrapper: {single['ms_per_step']:.1f} ms/step "
                     f"(joint / plain {one['ms_per_step'] / single['ms_per_step']:.2f})")
    return "\n".join(lines)
