"""A joint fit of two renders of one identity against each photograph's single fit.

One identity of the whole-head default model (``synthetic_case(seed=S)``),
rendered at yaw -25 deg (A) and at yaw 30 deg with a side light (B), 250^2;
each photograph fitted alone and both jointly, default settings (2 chains in
parallel). Prints, per fit: convergence, wall time, the posterior-mean diffuse
RMSE on the vertices both photographs saw and on those either saw, the mean
coefficient-only and predictive std there and on the vertices only one saw,
and the coverage of the 90 % intervals. Run as
``OPENBLAS_NUM_THREADS=1 python benchmarks/joint_vs_single.py [SEED] [OUT] [--held-out]``
(about 25 minutes on a 2-core machine; result folders in OUT, default
``/tmp/joint-vs-single-<SEED>``). With ``--held-out`` the person is a subject
the default model never saw (its detailed albedo on one shape) photographed
in two random scenes of the evaluation's ``sh`` scene.
"""
from __future__ import annotations

import json
import sys
import time

import numpy as np
from mcmcfit.jobs.model_spec import load_model_spec, resolve_model
from mcmcfit.jobs.fit_job import LoadedModel, fit_into_folder
from mcmcfit.jobs.joint_job import joint_fit_into_folder
from mcmcfit.jobs.synthetic_case import synthetic_case
from mcmcfit.outputs.truth import Truth
from albedo_model.io.model_files import file_sha256

args = [a for a in sys.argv[1:] if a != "--held-out"]
held_out = "--held-out" in sys.argv
seed = int(args[0]) if args else 0
root = args[1] if len(args) > 1 else f"/tmp/joint-vs-single-{seed}{'-held-out' * held_out}"
path = resolve_model("default")
loaded = LoadedModel(load_model_spec("default"), file_sha256(path), "default")
m = loaded.model
if held_out:
    # a subject the default model never saw (skin detail outside its span), its albedo on
    # one shape, photographed in two scenes of the evaluation's "sh" scene (SH light, read
    # noise, textured background, noisy landmarks)
    from types import SimpleNamespace

    from pipeline.synthetic.held_out import build_held_out_population
    from pipeline.synthetic.scene_render import render_scene
    from pipeline.synthetic.scenes import scene_spec

    h = build_held_out_population(60, 1, seed=2020).held_out[0]
    identity = np.zeros(m.ranks["shape"])
    identity[:10] = np.random.default_rng(seed).normal(size=10)
    cases = []
    for k in (1, 2):
        photo = render_scene(m, h.diffuse, h.specular, scene_spec("sh"), seed=[seed, k],
                             shape=identity)
        cases.append(SimpleNamespace(image=photo.image, landmarks=photo.landmarks,
                                     diffuse=h.diffuse, specular=h.specular,
                                     visible=photo.visible, truth=photo.truth))
        print(f"photograph {k}: yaw {np.degrees(photo.truth.pose.yaw):+.1f} deg", flush=True)
    A, B = cases
else:
    A = synthetic_case(m, seed=seed, yaw_deg=-25.0)
    B = synthetic_case(m, seed=seed, yaw_deg=30.0, side_light=True)
assert np.allclose(A.diffuse, B.diffuse)
times = {}
for name, c in (("A", A), ("B", B)):
    t0 = time.perf_counter()
    fit_into_folder(c.image, c.landmarks, loaded, f"{root}/{name}", seed=seed, force=True,
                    truth=Truth(c.diffuse, c.specular, c.visible, c.truth))
    times[name] = time.perf_counter() - t0
t0 = time.perf_counter()
joint_fit_into_folder([A.image, B.image], [A.landmarks, B.landmarks], loaded, f"{root}/J",
                      seed=seed, force=True,
                      truth=Truth(A.diffuse, A.specular, A.visible | B.visible, None))
times["J"] = time.perf_counter() - t0
both, union = A.visible & B.visible, A.visible | B.visible
only = {"A": A.visible & ~B.visible, "B": B.visible & ~A.visible}
rows = {}
for name in ("A", "B", "J"):
    z = np.load(f"{root}/{name}/posterior.npz")
    s = json.load(open(f"{root}/{name}/summary.json"))
    mean, std, lo, hi = z["diffuse_mean"], z["diffuse_std"], z["diffuse_lo"], z["diffuse_hi"]
    cstd, clo, chi = z["diffuse_coef_std"], z["diffuse_coef_lo"], z["diffuse_coef_hi"]
    t = A.diffuse
    def rmse(sel): return float(np.sqrt(np.mean((mean[sel] - t[sel]) ** 2)))
    def cov(sel, a, b): return float(np.mean((t[sel] >= a[sel]) & (t[sel] <= b[sel])))
    rows[name] = {"converged": s["converged"], "max_rhat": s["convergence"].get("max_rhat"),
                  "min_ess_bulk": s["convergence"].get("min_ess_bulk"),
                  "min_ess_tail": s["convergence"].get("min_ess_tail"),
                  "kept": s["stopping"].get("kept_steps"), "seconds": times[name],
                  "rmse_both": rmse(both), "rmse_union": rmse(union),
                  "std_both": float(std[both].mean()), "coef_std_both": float(cstd[both].mean()),
                  "std_onlyA": float(std[only["A"]].mean()),
                  "std_onlyB": float(std[only["B"]].mean()),
                  "coef_std_onlyA": float(cstd[only["A"]].mean()),
                  "coef_std_onlyB": float(cstd[only["B"]].mean()),
                  "cov_pred_union": cov(union, lo, hi), "cov_coef_union": cov(union, clo, chi),
                  "cov_coef_both": cov(both, clo, chi)}
print(json.dumps({"seed": seed, "n_both": int(both.sum()), "n_union": int(union.sum()),
                  "rows": rows}, indent=1))
