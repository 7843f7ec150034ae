"""Time per step and to convergence of a joint fit against the number of photographs (1, 2, 4).

One identity of the whole-head default model (``synthetic_case(seed=S)``)
rendered in the scenes of ``mcmcfit bench joint`` (yaw -25, 30, 0, 15 deg; a
side light in every second one), 250^2. The first N photographs are fitted
with the default settings (2 chains in parallel, the Gaussian sampler, the
convergence rule): N = 1 by ``mcmcfit fit``'s job, N >= 2 jointly. Printed per
N: converged, kept steps per chain, max R-hat, min bulk / tail ESS, the fit's
own time (``timings.total_s``), image-stage steps per second per chain and its
ratio to N = 1, min bulk-ESS per second of the image stage, and the diffuse
albedo RMSE and mean coefficient-only std on the vertices any photograph saw.

Run as ``OPENBLAS_NUM_THREADS=1 python benchmarks/joint_images.py [SEED] [OUT] [--images 1,2,4]``
(result folders in OUT, default ``/tmp/joint-images-<SEED>``; about 40 minutes
on a 2-core machine). The fits run one after the other, so their ratios share
the machine's speed only roughly: compare them with ``mcmcfit bench joint``'s
per-step ratios, which are measured in one process.
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np

from albedo_model.io.model_files import file_sha256
from mcmcfit.bench.joint_bench import SCENES
from mcmcfit.jobs.fit_job import LoadedModel, fit_into_folder
from mcmcfit.jobs.joint_job import joint_fit_into_folder
from mcmcfit.jobs.model_spec import load_model_spec, resolve_model
from mcmcfit.jobs.synthetic_case import synthetic_case
from mcmcfit.outputs.truth import Truth

argv = sys.argv[1:]
counts = (1, 2, 4)
if "--images" in argv:
    i = argv.index("--images")
    counts = tuple(int(v) for v in argv[i + 1].split(","))
    del argv[i:i + 2]
seed = int(argv[0]) if argv else 0
root = argv[1] if len(argv) > 1 else f"/tmp/joint-images-{seed}"
loaded = LoadedModel(load_model_spec("default"), file_sha256(resolve_model("default")), "default")
cases = [synthetic_case(loaded.model, seed=seed, yaw_deg=yaw, side_light=side)
         for yaw, side in SCENES[:max(counts)]]
rows = {}
for n in counts:
    use = cases[:n]
    visible = np.logical_or.reduce([c.visible for c in use])
    folder = f"{root}/n{n}"
    t0 = time.perf_counter()
    if n == 1:
        c = use[0]
        fit_into_folder(c.image, c.landmarks, loaded, folder, seed=seed, force=True,
                        truth=Truth(c.diffuse, c.specular, c.visible, c.truth))
    else:
        joint_fit_into_folder([c.image for c in use], [c.landmarks for c in use], loaded, folder,
                              seed=seed, force=True,
                              truth=Truth(use[0].diffuse, use[0].specular, visible, None))
    wall = time.perf_counter() - t0
    with open(f"{folder}/summary.json") as f:
        s = json.load(f)
    z = np.load(f"{folder}/posterior.npz")
    err = z["diffuse_mean"][visible] - use[0].diffuse[visible]
    conv, t = s["convergence"], s["timings"]
    kept = s["stopping"].get("kept_steps")
    rows[n] = {"converged": s["converged"], "kept_steps": kept,
               "max_rhat": conv.get("max_rhat"), "min_ess_bulk": conv.get("min_ess_bulk"),
               "min_ess_tail": conv.get("min_ess_tail"), "fit_s": t.get("total_s"),
               "wall_s": wall, "stage2_s": t.get("stage2_s"),
               "steps_per_s": t.get("stage2_steps_per_s"),
               "rmse": float(np.sqrt(np.mean(err ** 2))),
               "coef_std": float(z["diffuse_coef_std"][visible].mean())}
    print(json.dumps({n: rows[n]}), flush=True)
base = rows.get(1)
print("\n| images | converged | kept steps | max R-hat | min bulk / tail ESS | fit time (s) "
      "| steps/s per chain | time per step vs 1 | diffuse RMSE | coef std |")
print("|---|---|---|---|---|---|---|---|---|---|")
for n, r in rows.items():
    ratio = (base["steps_per_s"] / r["steps_per_s"]) if base and r["steps_per_s"] else None
    print(f"| {n} | {'yes' if r['converged'] else 'no'} | {r['kept_steps']} | "
          f"{r['max_rhat']:.4f} | {r['min_ess_bulk']:.0f} / {r['min_ess_tail']:.0f} | "
          f"{r['fit_s']:.0f} | {r['steps_per_s']:.2f} | "
          f"{'-' if ratio is None else f'{ratio:.2f}x'} | {r['rmse']:.5f} | {r['coef_std']:.5f} |")
