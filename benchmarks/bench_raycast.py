"""Ray-caster timings on a BFM-sized synthetic face (bumpy half-ellipsoid heightfield).

Prints median milliseconds per call: primary-ray cast at 128², 250², 512² with 1
and 2 threads (robust off and on), geometry update by in-place refit vs rebuild,
and the pose -> model-frame ray transform. Run as
``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_raycast.py [--repeats N]``.
Figures vary by up to ~1.5x between runs on a shared VM, and another busy
process takes the 2-thread gain away (see performance-notes.md).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from albedo_model import camera as cam
from albedo_model.render import raycast
from albedo_model.params import Pose, default_square, fit_to_image_size


def face_mesh(n_side: int = 232, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Bumpy half-ellipsoid heightfield: ``n_side**2`` vertices, ``2 (n_side-1)**2`` triangles.

    232 gives 53,824 vertices and 106,722 triangles (BFM 2017: 53,490 / 106,466).
    Model frame in mm, facing +z, about 170 x 220 x 100 mm.
    """
    rng = np.random.default_rng(seed)
    g = np.linspace(-1.0, 1.0, n_side)
    u, v = np.meshgrid(g, g)
    z = np.sqrt(np.clip(1.0 - u**2 - v**2, 0.0, None))
    bumps = sum(
        rng.normal(0, 0.02) * np.sin(rng.uniform(2, 12) * u + rng.uniform(0, 6))
        * np.cos(rng.uniform(2, 12) * v + rng.uniform(0, 6)) for _ in range(12)
    )
    pts = np.stack([85.0 * u, 110.0 * v, 100.0 * (z + bumps)], -1).reshape(-1, 3)
    idx = np.arange(n_side * n_side).reshape(n_side, n_side)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    tri = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3),
                          np.stack([a, d, c], -1).reshape(-1, 3)])
    return pts, tri.astype(np.int32)


def median_ms(fn, repeats: int) -> float:
    """Median wall time of consecutive calls (warm caches, as in a chain reusing one BVH)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=30)
    args = ap.parse_args(argv)
    verts, tris = face_mesh()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"mesh: {len(verts)} vertices, {len(tris)} triangles; cpus usable: "
          f"{raycast.default_threads()} of {os.cpu_count()}; load average {load:.2f}; "
          f"refit check: {raycast.refit_check()}")
    pose = Pose(translation=(0.0, 0.0, -1000.0))
    casters = {(th, rb): raycast.RayCaster(verts, tris, threads=th, robust=rb)
               for th in (1, 2) for rb in (False, True)}
    for res in (128, 250, 512):
        p = fit_to_image_size(default_square(), res, res)
        o, d = cam.camera_rays(p.camera, p.image_size, pose, p.view)
        far = p.camera.far - p.camera.near
        grid = (res, res)
        cover = casters[(1, False)].cast(o, d, tfar=far).mask.mean()
        row = [f"{res}x{res} (face {100 * cover:.0f}% of pixels):"]
        out = (np.empty_like(o), np.empty_like(d))
        fns = [lambda c=c: c.cast(o, d, tfar=far, image_shape=grid) for c in casters.values()]
        fns.append(lambda: casters[(1, False)]._scene.run(o, d, far, "INTERSECT", 1))
        fns.append(lambda: cam.camera_rays(p.camera, p.image_size, pose._replace(yaw=0.3),
                                           p.view, out=out))
        *cast_ms, raw, ms = (median_ms(fn, args.repeats) for fn in fns)
        for (th, rb), t in zip(casters, cast_ms):
            row.append(f"{th} thr{' robust' if rb else ''} {t:.2f} ms")
        print("  ".join(row))
        print(f"    ray transform (pose change, preallocated): {ms:.3f} ms; "
              f"bare embreex run (1 thr, no culling/leak checks): {raw:.2f} ms")

    rng = np.random.default_rng(1)
    deformed = [verts + rng.normal(0, 2.0, 3) * np.sin(verts / 40.0 + k) for k in range(4)]
    refit = raycast.RayCaster(verts, tris, update="refit")
    rebuild = raycast.RayCaster(verts, tris, update="rebuild")
    k = iter(range(10**9))
    ms_refit = median_ms(lambda: refit.update_vertices(deformed[next(k) % 4]), args.repeats)
    ms_rebuild = median_ms(lambda: rebuild.update_vertices(deformed[next(k) % 4]),
                           max(3, args.repeats // 5))
    print(f"geometry update: refit {ms_refit:.2f} ms ({refit.update_method}), "
          f"rebuild {ms_rebuild:.1f} ms")
    p = fit_to_image_size(default_square(), 250, 250)
    o, d = cam.camera_rays(p.camera, p.image_size, pose, p.view)
    for name, c in (("refit", refit), ("rebuild", rebuild)):
        c.update_vertices(deformed[0])
        ms = median_ms(lambda c=c: c.cast(o, d), args.repeats)
        print(f"    250x250 cast after {name}: {ms:.2f} ms ({c.threads} thr)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
