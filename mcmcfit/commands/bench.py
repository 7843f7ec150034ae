"""``mcmcfit bench``: benchmarks of the hot paths.

``mcmcfit bench render`` (ms per sampler step per proposal kind, against the naive path),
``mcmcfit bench fit`` (the default schedule on the demo case: time per stage and proposal kind,
accuracy against time) and ``mcmcfit bench joint`` (ms per step of a joint fit of 1, 2, 4
photographs of one face).

This module imports :mod:`albedo_model.errors`; :mod:`mcmcfit.bench`,
:mod:`mcmcfit.fitting.config` and :mod:`mcmcfit.jobs.model_spec` are imported when a
benchmark runs.
"""

from __future__ import annotations

import argparse
import sys

from albedo_model.errors import InputError

__all__ = ["add_fit_arguments", "add_render_arguments", "register", "run_fit", "run_joint",
           "run_render"]


def _int_list(text: str, what: str, minimum: int) -> list[int]:
    """Comma-separated integers >= ``minimum`` (argparse type helper)."""
    try:
        values = [int(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated {what}, got {text!r}")
    if not values or min(values) < minimum:
        raise argparse.ArgumentTypeError(f"{what} must be integers >= {minimum}, got {text!r}")
    return values


def _sizes(text: str) -> list[int]:
    return _int_list(text, "pixel sizes", 8)


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


def _counts(text: str) -> list[int]:
    return _int_list(text, "step counts", 1)


def add_fit_arguments(p: argparse.ArgumentParser) -> None:
    """Options of the fit benchmark (shared with ``python -m mcmcfit.bench``)."""
    p.add_argument("-o", "--output", metavar="PLOT.png", default=None,
                   help="write the accuracy-vs-time curve as a PNG plot")
    p.add_argument("--json", metavar="F.json", default=None, help="write all figures as JSON")
    p.add_argument("--model", default="default", help="model file or 'default' (default)")
    p.add_argument("--steps", type=int, default=None,
                   help="image-stage steps per chain (default: the default schedule)")
    p.add_argument("--landmark-steps", type=int, default=None,
                   help="landmark-stage steps per chain (default: the default schedule)")
    p.add_argument("--warmup-steps", type=int, default=None,
                   help="image-stage warm-up steps per chain (default: the default schedule)")
    p.add_argument("--chains", type=int, default=None, help="chains (default: FitConfig's)")
    p.add_argument("--checkpoints", type=_counts, default=[500, 1000, 2000, 5000, 10000],
                   metavar="N,N,...", help="image steps at which accuracy and time are reported "
                   "(default 500,1000,2000,5000,10000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the fit (default 0)")
    p.add_argument("--case-seed", type=int, default=0,
                   help="seed of the synthetic demo case (default 0)")
    p.add_argument("--size", type=int, default=250, help="image size in pixels (default 250)")
    p.add_argument("--mixing-cases", default="demo,yaw40-side-light", metavar="NAME,...",
                   help="cases of the ESS-per-second comparison with the reference's "
                   "random-walk schedule (default demo,yaw40-side-light; 'none' skips it)")
    p.add_argument("--quiet", action="store_true", help="no progress messages on stderr")


def _format_mixing(figures: dict) -> str:
    """Format the ESS-per-second table of :func:`mcmcfit.bench.mixing_bench.run_mixing_bench`."""
    lines = ["effective samples per second of the kept draws (bulk-ESS over the monitored "
             "quantities / wall time of the kept draws; same posterior, same steps):",
             f"{'case':<18} {'schedule':<10} {'min ESS/s':>10} {'median ESS/s':>13} "
             f"{'worst quantity':<24} {'max R-hat':>9} {'RMSE':>7} {'cov90':>6}"]
    for case, f in figures.items():
        for label in ("default", "reference"):
            d = f[label]
            lines.append(f"{case:<18} {label:<10} {d['min_ess_per_s']:>10.3f} "
                         f"{d['median_ess_per_s']:>13.2f} {d['worst'][:24]:<24} "
                         f"{d['max_rhat']:>9.3f} {d['rmse']:>7.4f} {d['coverage']:>6.1%}")
        lines.append(f"{case:<18} ratio      {f['ratio_min_ess_per_s']:>10.1f}x "
                     f"{f['ratio_median_ess_per_s']:>12.1f}x")
    return "\n".join(lines)


def register(subparsers) -> None:
    """Add ``bench`` with its ``render``, ``fit`` and ``joint`` actions."""
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
    p = sub.add_parser(
        "fit", help="the default schedule on the demo case: time split and accuracy vs time",
        description="Fit the demo case (a synthetic face of the model with known truth, "
        "250x250, seed 0) with the default schedule. Prints the wall time per stage and per "
        "proposal kind, the ratio to the reference pipeline's ~20 min per fit, and the "
        "posterior-mean albedo RMSE and 90 % interval coverage against the truth at "
        "checkpoints along the image stage, beside the wall time at each.",
    )
    add_fit_arguments(p)
    p.set_defaults(func=run_fit)
    p = sub.add_parser(
        "joint", help="ms per sampler step of a joint fit of 1, 2, 4 photographs of one face",
        description="Render one identity of the model in up to four scenes (yaw -25, 30, 0, "
        "15 deg, side light in every second), build each image's targets and random-walk "
        "schedule as a fit does, lift them to the joint posterior (the albedo's conditional "
        "over every image) and time sampler steps per number of images, against one image "
        "and against the plain single-image target.",
    )
    p.add_argument("--images", type=lambda t: _int_list(t, "numbers of images", 1),
                   default=[1, 2, 4], metavar="N,N,...", help="numbers of images (default 1,2,4)")
    p.add_argument("--steps", type=int, default=600, help="timed steps each (default 600)")
    p.add_argument("--warmup", type=int, default=60, help="untimed steps first (default 60)")
    p.add_argument("--size", type=int, default=250, help="image size in pixels (default 250)")
    p.add_argument("--seed", type=int, default=0, help="the identity and the sampler (default 0)")
    p.add_argument("--model", default="default", help="model file or 'default' (default)")
    p.add_argument("--json", metavar="F.json", default=None, help="write the figures as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress messages on stderr")
    p.set_defaults(func=run_joint)


def run_render(args: argparse.Namespace) -> int:
    """Run the render benchmark and print its table."""
    from mcmcfit.bench.render_bench import run_render_bench
    from mcmcfit.bench.render_report import format_table

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


def run_fit(args: argparse.Namespace) -> int:
    """Run the fit benchmark, print its report, write the plot / JSON if asked."""
    from pathlib import Path

    from mcmcfit.bench.fit_bench import (
        format_fit_bench,
        plot_fit_bench,
        run_fit_bench,
        write_json,
    )
    from mcmcfit.fitting.config import FitConfig
    from mcmcfit.jobs.model_spec import load_model_spec

    changes = {k: v for k, v in (("steps", args.steps), ("landmark_steps", args.landmark_steps),
                                 ("warmup_steps", args.warmup_steps), ("chains", args.chains))
               if v is not None}
    cfg = FitConfig().replace(**changes)
    if args.size < 32:
        raise InputError(f"--size must be >= 32, got {args.size}")
    for out in (args.output, args.json):
        if out is not None and not Path(out).parent.exists():
            raise InputError(f"{Path(out).parent}: output folder does not exist")
    cases = [c for c in args.mixing_cases.split(",") if c and c != "none"]
    if cases:
        from mcmcfit.bench.mixing_bench import CASES, run_mixing_bench

        unknown = [c for c in cases if c not in CASES]
        if unknown:
            raise InputError(f"unknown --mixing-cases {unknown}; known: {sorted(CASES)}")
    quiet = args.quiet
    model = load_model_spec(args.model, progress=not quiet)
    last = {}

    def progress(stage, chain, done, total):
        if quiet or (done % 1000 and done != total):
            return
        key = (stage, chain)
        if last.get(key) != done:
            last[key] = done
            print(f"chain {chain} {stage}: {done}/{total}", file=sys.stderr, flush=True)

    bench = run_fit_bench(model, config=cfg, seed=args.seed, case_seed=args.case_seed,
                          size=args.size, checkpoints=args.checkpoints, progress=progress)
    print(format_fit_bench(bench))
    mixing = None
    if cases:
        log = None if quiet else (lambda case, label: print(
            f"mixing: {case} with the {label} schedule", file=sys.stderr, flush=True))
        mixing = run_mixing_bench(model, config=cfg, seed=args.seed, cases=tuple(cases),
                                  size=args.size, progress=log)
        print(_format_mixing(mixing))
    if args.output is not None:
        plot_fit_bench(bench, args.output)
        print(f"wrote {args.output}")
    if args.json is not None:
        write_json(bench, args.json, extra={"mixing": mixing} if mixing else None)
        print(f"wrote {args.json}")
    return 0


def run_joint(args: argparse.Namespace) -> int:
    """Run the joint-fit step benchmark and print its table."""
    import json
    from pathlib import Path

    from mcmcfit.bench.joint_bench import format_joint_bench, run_joint_bench
    from mcmcfit.jobs.model_spec import load_model_spec

    if args.size < 32:
        raise InputError(f"--size must be >= 32, got {args.size}")
    if args.json is not None and not Path(args.json).parent.exists():
        raise InputError(f"{Path(args.json).parent}: output folder does not exist")
    model = load_model_spec(args.model, progress=not args.quiet)
    log = None if args.quiet else (lambda msg: print(msg, file=sys.stderr, flush=True))
    result = run_joint_bench(model, images=args.images, steps=args.steps, warmup=args.warmup,
                             size=args.size, seed=args.seed, log=log)
    print(format_joint_bench(result))
    if args.json is not None:
        Path(args.json).write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
        print(f"wrote {args.json}")
    return 0
