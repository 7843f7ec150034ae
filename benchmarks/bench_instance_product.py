"""Micro-benchmark: the renderer's full PCA instance, float64 ``B @ c`` against float32 ``c @ B_t``.

Every Metropolis-Hastings step that changes many shape or albedo coefficients
(Crank-Nicolson, HMC, the exact conditionals) recomputes the instance the
renderer reads (:meth:`albedo_model.render.instances.InstanceUpdater.instance`).
The product is memory-bound: the float64 basis stored (rows, k) reads 8 bytes
per entry, the float32 transposed basis the updater already keeps for its block
updates reads 4, contiguously. This times both on the default model's shape and
stacked diffuse + specular albedo bases, called round-robin so machine load
affects them alike, and prints the ratio and the largest difference (in units
of the float32 spacing of the instance's largest entry).

Usage: ``python benchmarks/bench_instance_product.py [--reps 300]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from albedo_model.io.model_files import load_model
from albedo_model.render.instances import InstanceUpdater


def main(argv: list[str] | None = None) -> None:
    """Time the float64 and the float32 full instance of the default model's parts."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=300)
    args = ap.parse_args(argv)
    model = load_model("default")
    updater = InstanceUpdater()
    rng = np.random.default_rng(0)
    for label, parts in (("shape", (model.shape,)),
                         ("albedo (diffuse + specular)", (model.diffuse, model.specular))):
        c = rng.normal(size=parts[0].rank)

        def float64(parts=parts, c=c):
            return np.concatenate([p.instance(c) for p in parts]).astype(np.float32)

        def float32(parts=parts, c=c):
            return updater.instance([(parts, c)])

        calls = {"float64 B @ c": float64, "float32 c @ B_t": float32}
        times = {k: [] for k in calls}
        for f in calls.values():
            f()
        for _ in range(args.reps):
            for k, f in calls.items():
                t = time.perf_counter()
                f()
                times[k].append(time.perf_counter() - t)
        med = {k: 1e3 * float(np.median(v)) for k, v in times.items()}
        exact = np.concatenate([p.instance(c) for p in parts])
        ulps = np.abs(float32() - exact).max() / np.spacing(np.float32(np.abs(exact).max()))
        rows = sum(p.dim for p in parts)
        print(f"{label}: {rows} x {parts[0].rank}")
        for k, ms in med.items():
            print(f"  {k:18s} median {ms:6.2f} ms")
        print(f"  float64 / float32 = {med['float64 B @ c'] / med['float32 c @ B_t']:.1f}x; "
              f"largest difference {ulps:.1f} float32 spacings")


if __name__ == "__main__":
    main()
