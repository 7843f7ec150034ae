"""The climb to the mode: exact gradients with a kept precision against subset Jacobians.

Every fit of the Gaussian sampler climbs to its posterior's mode with
Levenberg-Marquardt steps (:func:`mcmcfit.fitting.mode.find_mode`). Each step
needs a gradient and a precision. The old climb formed both from the pixel
Jacobian of a random 4,000-pixel subset of the region on every step (0.17-0.3 s at
250^2: one forward-mode pass per parameter), so its gradient carried the
subset's noise. The new climb takes the exact gradient over every region pixel
(one reverse pass, ~30 ms, the HMC move's) on every step and evaluates the
subset precision once per few accepted steps.

For each demo face (``synthetic_case(seed=S)``) this builds the fit's
posterior over the interior region of the true render (noise sd 0.01, the
demo's), starts where a landmark fit leaves the image stage (the true pose
and camera, every coefficient 0, the light 1.3x too bright) and runs the fit's
two climbs (the appearance alone, then everything) both ways from that start,
in one run, alternating. It prints each way's wall time, accepted steps and
the log density reached, and the ratios.

Usage: ``python benchmarks/bench_climb.py [--faces 0 1 2 3 4 5] [--steps 30]``
(about 4 minutes).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from albedo_model.io.model_files import load_model
from albedo_model.params import SHLight
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.gaussian_stage import appearance_coordinates, sampling_coordinates
from mcmcfit.fitting.initialisation import initial_params
from mcmcfit.fitting.mode import find_mode, region_of
from mcmcfit.fitting.problem import FitProblem, build_posterior
from mcmcfit.jobs.synthetic_case import synthetic_case
from mcmcfit.proposal_data.face_pixels import unsaturated
from mcmcfit.sampling.param_vector import ParamLayout
from mcmcfit.targets.curvature import PosteriorCurvature, SceneCaster, coordinate_gradient
from mcmcfit.targets.noise_model import fixed_noise


def _start(case, template):
    """The truth's pose and camera with zero coefficients and a too-bright light."""
    t = case.truth
    light = SHLight(np.asarray(t.environment_map.coefficients) * 1.3)
    return template._replace(pose=t.pose, camera=t.camera, environment_map=light)


def climb(post, caster, coords, start, *, steps: int, exact: bool, seed: int):
    """Run the fit's two climbs (appearance, then all) one way: (seconds, steps, log density)."""
    curvature = PosteriorCurvature(post.face, coords.layout, caster=caster)
    gradient = coordinate_gradient(curvature, coords) if exact else None
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    first = find_mode(post.face, curvature, coords, start, rng=rng, max_steps=steps,
                      free=appearance_coordinates(coords), gradient=gradient)
    second = find_mode(post.face, curvature, coords, first.params, rng=rng, max_steps=steps,
                       gradient=gradient)
    return time.perf_counter() - t0, first.iterations + second.iterations, second.log_density


def main(argv: list[str] | None = None) -> None:
    """Print, per face, both climbs' time, steps and log density reached, and the ratios."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--faces", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    ap.add_argument("--steps", type=int, default=30, help="most steps per climb (the fit's)")
    args = ap.parse_args(argv)
    model = load_model("default")
    cfg = FitConfig()
    caster = SceneCaster(model)
    print("face | subset Jacobians: s, steps, log density | exact gradient: s, steps, "
          "log density | time ratio old/new, density gain new-old (nats)")
    ratios = []
    for seed in args.faces:
        case = synthetic_case(model, seed=seed, size=250)
        h, w = case.image.shape[:2]
        template = initial_params(model, w, h, n_shape=cfg.n_shape, n_albedo=cfg.n_albedo,
                                  n_expression=cfg.n_expression)
        layout = ParamLayout.for_params(template)
        problem = FitProblem(case.image, case.landmarks, None, None, model, cfg, template,
                             layout)
        start = _start(case, template)
        noise = fixed_noise(0.01, 1.0, 0.0)
        whole = build_posterior(problem, noise)
        usable = unsaturated(whole.image_target.linear.reshape(-1, 3))
        region = region_of(caster, case.truth, usable, erode=cfg.region_erode,
                           contour_band=cfg.region_band)
        post = build_posterior(problem, noise, renderer=whole.renderer,
                               geometry=whole.geometry, region=region)
        coords = sampling_coordinates(start)
        climb(post, caster, coords, start, steps=2, exact=True, seed=seed)  # compile both
        climb(post, caster, coords, start, steps=2, exact=False, seed=seed)
        old = climb(post, caster, coords, start, steps=args.steps, exact=False, seed=seed)
        new = climb(post, caster, coords, start, steps=args.steps, exact=True, seed=seed)
        ratios.append(old[0] / new[0])
        print(f"{seed} | {old[0]:6.1f} s {old[1]:3d} {old[2]:12.1f} | {new[0]:6.1f} s "
              f"{new[1]:3d} {new[2]:12.1f} | {old[0] / new[0]:5.2f}x  {new[2] - old[2]:+8.1f}")
    print(f"time ratio old/new: median {np.median(ratios):.2f}x "
          f"(range {min(ratios):.2f}-{max(ratios):.2f}x)")


if __name__ == "__main__":
    main()
