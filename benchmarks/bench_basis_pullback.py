"""Micro-benchmark: the PCA product and its pullback, basis stored (rows, k) or transposed (k, rows).

The posterior's gradient (:meth:`albedo_model.render.jacobian.PixelJacobian.gaussian_value_and_grad`)
forms the vertices ``mean + B_shape c`` and the albedo table ``mean + B_albedo a`` of
the whole model, then pulls the pixels' cotangents back through both products.
XLA-CPU compiles the pullback of ``B @ c`` (``B`` row-major, (rows, k)) into a
strided transposed product several times slower than the forward one; with the
basis stored transposed, ``c @ B_t`` and its pullback ``B_t @ g`` both read it
contiguously. This compares the two orientations on the default model's own
bases (float32, one XLA thread), forward alone and forward + pullback, called
round-robin so machine load affects them alike, and prints the ratios.

Usage: ``python benchmarks/bench_basis_pullback.py [--reps 200]``.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("XLA_FLAGS",
                      "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.io.model_files import load_model


def _programs(basis: np.ndarray) -> dict:
    """Forward and forward+pullback programs of ``sum((B c)^2)`` in both orientations."""
    rows = jnp.asarray(basis, jnp.float32)
    cols = jnp.asarray(np.ascontiguousarray(basis.T), jnp.float32)

    def stored_rows(c):
        return jnp.sum(jnp.square(rows @ c))

    def stored_transposed(c):
        return jnp.sum(jnp.square(c @ cols))

    return {"(rows, k): B @ c": stored_rows, "(k, rows): c @ B_t": stored_transposed}


def main(argv: list[str] | None = None) -> None:
    """Time both orientations on the default model's shape and albedo bases."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=200)
    args = ap.parse_args(argv)
    model = load_model("default")
    ks = min(50, model.shape.rank)
    ka = min(50, model.diffuse.rank)
    albedo = np.concatenate([model.diffuse.scaled_basis[:, :ka].reshape(-1, 3, ka),
                             model.specular.scaled_basis[:, :ka].reshape(-1, 3, ka)],
                            axis=1).reshape(-1, ka)
    for label, basis in (("shape", model.shape.scaled_basis[:, :ks]),
                         ("albedo (diffuse + specular)", albedo)):
        progs = _programs(np.asarray(basis, np.float64))
        c = jnp.asarray(np.random.default_rng(0).normal(size=basis.shape[1]), jnp.float32)
        calls = {}
        for name, f in progs.items():
            calls[(name, "forward")] = jax.jit(f)
            calls[(name, "forward + pullback")] = jax.jit(jax.value_and_grad(f))
        times = {k: [] for k in calls}
        for f in calls.values():
            jax.block_until_ready(f(c))
        for _ in range(args.reps):
            for k, f in calls.items():
                t = time.perf_counter()
                jax.block_until_ready(f(c))
                times[k].append(time.perf_counter() - t)
        print(f"{label}: basis {basis.shape[0]} x {basis.shape[1]} float32")
        med = {k: 1e3 * float(np.median(v)) for k, v in times.items()}
        for k, ms in med.items():
            print(f"  {k[0]:20s} {k[1]:20s} median {ms:6.2f} ms")
        names = list(progs)
        for part in ("forward", "forward + pullback"):
            print(f"  {part}: stored (rows, k) / stored transposed = "
                  f"{med[(names[0], part)] / med[(names[1], part)]:.1f}x")


if __name__ == "__main__":
    main()
