"""``mcmcfit bench render``: ms per sampler step per proposal kind, against the naive path."""

from __future__ import annotations

import argparse
import sys

from albedo_model.errors import InputError

__all__ = ["register", "run_render"]


def _sizes(text: str) -> list[int]:
    try:
        sizes = [int(s) for s in text.replace(" ", "").split(",") if s]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated pixel sizes, got {text!r}")
    if not sizes or min(sizes) < 8:
        raise argparse.ArgumentTypeError(f"sizes must be integers >= 8, got {text!r}")
    return sizes


def add_render_arguments(p: argparse.ArgumentParser) -> None:
    """Options of the render benchmark (shared with ``python -m mcmcfit.bench``)."""
    p.add_argument("--sizes", type=_sizes, default=[128, 250, 512], metavar="N,N,...",
                   help="square image sizes in pixels (default 128,250,512)")
    p.add_argument("--steps", type=int, default=40,
                   help="timed steps per proposal kind and size (median; default 40)")
    p.add_argument("--naive-steps", type=int, default=None, metavar="N",
                   help="timed steps of the naive path (default min(steps, 10))")
    p.add_argument("--threads", type=int, default=None, choices=(1, 2),
                   help="ray-casting threads (default: min(2, CPUs))")
    p.add_argument("--warmup", type=int, default=3, help="untimed steps first (compiles)")
    p.add_argument("--seed", type=int, default=0, help="seed of the model and the proposals")
    p.add_argument("--grid", type=int, default=232, metavar="N",
                   help="model grid N x N (default 232: 53,824 vertices, 106,722 triangles)")
    p.add_argument("--quiet", action="store_true", help="no progress messages on stderr")


def register(subparsers) -> None:
    """Add ``bench`` with its ``render`` action."""
    parser = subparsers.add_parser(
        "bench", help="benchmarks of the hot paths",
        description="Benchmarks of the hot paths.",
    )
    sub = parser.add_subparsers(dest="bench_command", metavar="BENCHMARK", required=True)
    p = sub.add_parser(
        "render", help="ms per sampler step per proposal kind (pose, shape, albedo, light)",
        description="Time sampler steps (Renderer.update + shading fused with a Gaussian pixel "
        "log-likelihood, accept/reject alternating) on a synthetic 53k-vertex face at several "
        "image sizes, with and without the specular term, and the naive path that recomputes "
        "everything (new Embree scene, full instance, NumPy normals, unspecialised shader).",
    )
    add_render_arguments(p)
    p.set_defaults(func=run_render)


def run_render(args: argparse.Namespace) -> int:
    """Run the render benchmark and print its table."""
    from mcmcfit.bench.render_bench import format_table, run_render_bench

    if args.steps < 1 or args.warmup < 0 or (args.naive_steps is not None and args.naive_steps < 1):
        raise InputError("--steps and --naive-steps must be >= 1, --warmup >= 0")
    if args.grid < 8:
        raise InputError(f"--grid must be >= 8, got {args.grid}")
    log = None if args.quiet else (lambda msg: print(msg, file=sys.stderr, flush=True))
    result = run_render_bench(args.sizes, args.steps, threads=args.threads, warmup=args.warmup,
                              naive_steps=args.naive_steps, seed=args.seed, grid=args.grid,
                              log=log)
    print(format_table(result))
    return 0
