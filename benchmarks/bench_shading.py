"""Micro-benchmark of the per-pixel shading: specialised shaders vs the naive one.

A bumpy half-ellipsoid height field (~54k vertices, ~107k triangles, close to the
BFM's 53k / 106k) is seen along -z; its hits are computed analytically (the
grid cell under each pixel and exact barycentrics), so no ray caster is needed
and the hit pattern is as coherent as a real render. The face covers
``--coverage`` of the pixels. Inputs are device-resident, as in the sampler.

Usage: ``python benchmarks/bench_shading.py [--size 250] [--reps 200]``.
Prints the median and minimum ms per call after compilation (all variants are
called round-robin, so machine load affects them alike) and the first-call
(trace + compile) time of each shader.
"""

from __future__ import annotations

import argparse
import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from albedo_model.model import vertex_normals
from albedo_model.params import ColorTransform, DirectionalLight, SHLight, default_square
from albedo_model.shading.interpolation import interpolate_albedo, interpolate_geometry, pixel_hits
from albedo_model.shading.image_formation import (
    Effects, build_shader, pixel_shader_function, shader_function, shading_params,
)
from albedo_model.shading.naive import shade_naive


def heightfield_hits(size: int, grid: int, coverage: float):
    """Grid mesh z = f(x, y) over [-1, 1]^2 and its per-pixel hits seen along -z."""
    xs = np.linspace(-1.0, 1.0, grid)
    gx, gy = np.meshgrid(xs, xs)
    gz = 0.8 * np.sqrt(np.clip(1.0 - gx**2 - gy**2, 0.0, None)) + 0.01 * np.sin(40 * gx) * np.cos(37 * gy)
    verts = np.stack([gx.ravel(), -gy.ravel(), gz.ravel()], 1)
    idx = np.arange(grid * grid).reshape(grid, grid)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    tris = np.empty((2 * (grid - 1) ** 2, 3), np.int32)
    tris[0::2] = np.stack([a, c, b], 1)
    tris[1::2] = np.stack([b, c, d], 1)
    row, col = np.mgrid[0:size, 0:size]
    fx_all = (col + 0.5) / size * (grid - 1)
    fy_all = (row + 0.5) / size * (grid - 1)
    cx = np.minimum(fx_all.astype(int), grid - 2)
    cy = np.minimum(fy_all.astype(int), grid - 2)
    fx, fy = fx_all - cx, fy_all - cy
    second = fx + fy > 1.0
    prim = (2 * (cy * (grid - 1) + cx) + second).astype(np.int32)
    u = np.where(second, 1.0 - fx, fy)
    v = np.where(second, fx + fy - 1.0, fx)
    radius = np.hypot((col + 0.5) / size * 2 - 1, (row + 0.5) / size * 2 - 1)
    prim[radius > np.sqrt(coverage * 4.0 / np.pi)] = -1
    bary = np.stack([u.ravel(), v.ravel()], 1).astype(np.float32)
    focal = 3.75 * size
    dirs = np.stack([(col.ravel() - size / 2) / focal, -(row.ravel() - size / 2) / focal,
                     -np.ones(size * size)], 1).astype(np.float32)
    return verts, tris, prim.ravel(), bary, dirs


def _compile_ms(fn, args) -> float:
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    return 1e3 * (time.perf_counter() - t0)


def _interleaved_ms(fns: dict, args, reps: int) -> dict[str, tuple[float, float]]:
    """Median and minimum ms per call, calling the functions round-robin.

    Round-robin keeps the comparison fair when other processes load the machine.
    """
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(reps):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            jax.block_until_ready(fn(*args))
            times[name].append(time.perf_counter() - t0)
    return {k: (1e3 * float(np.median(v)), 1e3 * float(np.min(v))) for k, v in times.items()}


def _fused_ssd(effects: Effects):
    shader = shader_function(effects)

    def ssd(*args):
        *shade_args, target = args
        out = shader(*shade_args)
        sq = sum((out.rgb[c] - target[c]) ** 2 for c in range(3))
        return jnp.sum(jnp.where(out.mask, sq, 0.0))

    return jax.jit(ssd)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=250, help="image width = height (px)")
    parser.add_argument("--grid", type=int, default=232, help="mesh grid resolution")
    parser.add_argument("--coverage", type=float, default=0.62)
    parser.add_argument("--reps", type=int, default=200)
    args = parser.parse_args(argv)

    rng = np.random.default_rng(0)
    verts, tris, prim, bary, dirs = heightfield_hits(args.size, args.grid, args.coverage)
    normals = vertex_normals(verts, tris).astype(np.float32)
    n = len(verts)
    diffuse = rng.uniform(0.2, 0.8, (n, 3)).astype(np.float32)
    specular = rng.uniform(0.0, 0.3, (n, 3)).astype(np.float32)
    shadow = (rng.random(len(prim)) > 0.2).astype(np.float32)
    params = default_square()._replace(
        environment_map=SHLight(rng.normal(0.0, 0.2, (9, 3)) + SHLight.frontal().coefficients),
        directional_light=DirectionalLight((0.1,) * 3, (0.5,) * 3, (0.3, 0.4, 1.0), (0.2,) * 3),
        color_transform=ColorTransform((1.05, 0.95, 1.0), 0.9, (0.01, 0.0, -0.01)),
    )
    sp = shading_params(params, np.eye(3))
    inputs = [jax.device_put(x) for x in (tris, normals, diffuse, specular, prim, bary, dirs)]
    inputs += [sp, jax.device_put(shadow)]
    print(f"image {args.size}x{args.size}, {n} vertices, {len(tris)} triangles, "
          f"coverage {np.mean(prim >= 0):.1%}, {jax.device_count()} device(s), jax {jax.__version__}")

    cases = {
        "SH only (no specular)": Effects(),
        "+ specular": Effects(specular=True),
        "+ specular + directional": Effects(specular=True, directional=True),
        "+ spec + dir + shadows + colour + gamma": Effects(
            specular=True, directional=True, shadows=True, color_transform=True, gamma=True),
    }
    fns, compile_ms = {}, {}
    for name, eff in cases.items():
        fns[name] = build_shader(eff)
        compile_ms[name] = _compile_ms(fns[name], inputs)
        fns["naive: " + name] = functools.partial(shade_naive, eff)
        compile_ms["naive: " + name] = _compile_ms(fns["naive: " + name], inputs)
    timing = _interleaved_ms(fns, inputs, args.reps)
    print(f"{'effects':42s} {'median ms':>9s} {'min ms':>7s} {'compile ms':>10s}"
          f" {'naive med':>9s} {'naive min':>9s} {'speed-up':>8s}")
    for name in cases:
        (med, low), (nmed, nlow) = timing[name], timing["naive: " + name]
        print(f"{name:42s} {med:9.3f} {low:7.3f} {compile_ms[name]:10.0f}"
              f" {nmed:9.3f} {nlow:9.3f} {nmed / med:8.1f}")
    first = "naive: " + next(iter(cases))
    print(f"naive compile (one function for all effect sets): {compile_ms[first]:.0f} ms")

    # Shading composed with a masked sum of squared differences in one jit, as a
    # likelihood would do it: XLA fuses the image away.
    target = tuple(jax.device_put(rng.random(len(prim)).astype(np.float32)) for _ in range(3))
    fused = {name: _fused_ssd(eff) for name, eff in cases.items()}
    fused_compile = {name: _compile_ms(fn, inputs + [target]) for name, fn in fused.items()}
    fused_timing = _interleaved_ms(fused, inputs + [target], args.reps)
    print(f"{'shade + SSD in one jit':42s} {'median ms':>9s} {'min ms':>7s} {'compile ms':>10s}")
    for name in cases:
        med, low = fused_timing[name]
        print(f"{name:42s} {med:9.3f} {low:7.3f} {fused_compile[name]:10.0f}")

    # What a light / colour step costs with the renderer's cached pixel attributes:
    # shading from interpolated (P,) arrays, no gathers.
    hits = pixel_hits(*(inputs[i] for i in (0, 4, 5)))
    full = Effects(specular=True, directional=True, directional_specular_map=True)
    geometry = interpolate_geometry(full, hits, inputs[1], inputs[6], sp.rotation)
    albedo = interpolate_albedo(full, hits, inputs[2], inputs[3])
    pixel_args = [geometry, albedo, sp, inputs[8]]
    pixel = {name: jax.jit(pixel_shader_function(eff)) for name, eff in cases.items()}
    pixel_compile = {name: _compile_ms(fn, pixel_args) for name, fn in pixel.items()}
    pixel_timing = _interleaved_ms(pixel, pixel_args, args.reps)
    print(f"{'cached pixel attributes (light step)':42s} {'median ms':>9s} {'min ms':>7s}"
          f" {'compile ms':>10s}")
    for name in cases:
        med, low = pixel_timing[name]
        print(f"{name:42s} {med:9.3f} {low:7.3f} {pixel_compile[name]:10.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
