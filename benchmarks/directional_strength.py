"""A move of the directional light's strength: with its own block (new) against the whole light's.

The SH light's exact conditional and the shading block draw the directional
light's RGB strength, not its direction. Declared as the whole light
(``Block.DIRECTIONAL``, the old table) such a step re-cast one shadow ray per
face pixel; declared as ``Block.DIRECTIONAL_STRENGTH`` it reuses the cast
shadows of the state it starts from. Both are timed, interleaved, on the
synthetic face model at ``--size`` with a side light and cast shadows on;
each step is ``update`` + the image log likelihood's device read-out, and is
rejected (the chain stays at its state), as most steps are.

Usage: ``python benchmarks/directional_strength.py [--size 250] [--steps 200]``.
Prints the median ms per step of each, their ratio and the shadow rays per step.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from albedo_model.params import Block, DirectionalLight
from albedo_model.render.renderer import Renderer
from mcmcfit.bench.render_bench import face_scene
from mcmcfit.bench.synthetic_face import synthetic_face_model


def main() -> None:
    """Time both declarations of a strength step and print the ratio."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=250)
    ap.add_argument("--steps", type=int, default=200)
    args = ap.parse_args()
    model = synthetic_face_model()
    params = face_scene(model, args.size)._replace(directional_light=DirectionalLight.from_angles(
        0.7, 0.35, (0.6, 0.55, 0.5), shininess=20.0))
    renderer = Renderer(model, shadows=True, directional_specular_map=True, threads=1)
    state = renderer.init_state(params)
    rng = np.random.default_rng(0)
    declared = {"old: Block.DIRECTIONAL": Block.DIRECTIONAL,
                "new: Block.DIRECTIONAL_STRENGTH": Block.DIRECTIONAL_STRENGTH}
    times = {k: [] for k in declared}
    rays = {k: 0 for k in declared}
    for i in range(args.steps + 5):
        for name, touched in declared.items():
            strength = tuple(float(v) for v in 0.55 + 0.05 * rng.normal(size=3))
            moved = params._replace(directional_light=params.directional_light._replace(
                diffuse=strength, specular=strength))
            before = renderer.ray_counts["shadow"]
            t0 = time.perf_counter()
            cand = renderer.update(state, moved, touched)
            np.asarray(renderer.image(cand).image).sum()
            dt = time.perf_counter() - t0
            renderer.reject()
            if i >= 5:  # the first steps compile
                times[name].append(dt)
                rays[name] += renderer.ray_counts["shadow"] - before
    med = {k: 1e3 * float(np.median(v)) for k, v in times.items()}
    for k in declared:
        print(f"{k:34s} {med[k]:7.2f} ms/step  {rays[k] / args.steps:8.0f} shadow rays/step")
    old, new = med.values()
    print(f"ratio old / new: {old / new:.2f}x ({args.size}^2, {args.steps} steps each, interleaved)")


if __name__ == "__main__":
    main()
