"""``mcmcfit evaluate -o EVAL``: the paper's held-out experiment (Table 1), out of model.

This module imports :mod:`albedo_model.errors` and :mod:`mcmcfit.commands.fit`;
:mod:`mcmcfit.evaluation`, :mod:`mcmcfit.batch.worker_env` and
:mod:`pipeline.synthetic` modules are imported when the command runs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from albedo_model.errors import InputError
from mcmcfit.commands.batch import positive_int
from mcmcfit.commands.fit import add_schedule_arguments, cli_warnings, config_from_args

__all__ = ["options_from_args", "register", "run"]

_HELP = """\
Build a population of synthetic subjects with the synthetic lightstage, a
model WITHOUT the K held-out subjects (intrinsic: linear diffuse and
specular albedo) and a baked-texture comparison model of the same training
subjects (BFM 2017's way: shading and highlights baked in, gamma-encoded),
photograph each held-out subject (skin detail outside the model's span) in
each scene, fit every photograph with every model through the batch engine
(resumable: run the same command again; failures recorded), and score the
recovered albedo against the truth on the vertices visible in the true view.

Models: intrinsic; baked (colour taken as camera sRGB values, as the
reference does); baked-gamma (the baked textures decoded to linear: the
paper's "we applied gamma for both models").
Scenes: sh (in-model control), ambient (the paper's protocol: near-ambient
light, specular, read+shot noise, JPEG, white-balance error), directional
(+ a side light with cast shadows), profile (yaw 45-70 deg), dark
(Fitzpatrick V-VI subjects).

Writes EVAL/cases.json, models/, cases/, truth/, fits/<model>/...,
table.md, table.csv, calibration.png, accuracy_time.png, report.html and
results.json. --score-only re-scores the existing fits.
"""


def register(subparsers) -> None:
    """Add the ``evaluate`` command."""
    p = subparsers.add_parser(
        "evaluate", help="the paper's held-out experiment (Table 1): accuracy and calibration",
        description=_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-o", "--output", required=True, metavar="EVAL", help="evaluation folder")
    p.add_argument("--subjects", type=positive_int, default=60, metavar="N",
                   help="training subjects of the models (default 60)")
    p.add_argument("--held-out", type=positive_int, default=6, metavar="K",
                   help="held-out subjects, never seen by the models (default 6)")
    p.add_argument("--scenes", default="ambient,directional", metavar="S,S",
                   help="comma-separated scenes: sh, ambient, directional, profile, dark "
                   "(default ambient,directional)")
    p.add_argument("--models", default="intrinsic,baked,baked-gamma", metavar="M,M",
                   help="comma-separated models: intrinsic, baked, baked-gamma (default all)")
    p.add_argument("--size", type=int, default=250, metavar="PX",
                   help="image width and height (default 250)")
    p.add_argument("--detail", default="all", metavar="KINDS",
                   help="skin detail of the held-out subjects: 'all', 'none' or a comma list of "
                   "freckles, moles, scars, stubble, makeup, uneven_tone")
    p.add_argument("--population-seed", type=int, default=2020, metavar="S",
                   help="seed of the subjects, their detail and the scenes (default 2020: the "
                   "default model's; with --subjects 60 its cached file is the intrinsic model)")
    p.add_argument("--score-only", action="store_true",
                   help="fit nothing: score the existing result folders again")
    p.add_argument("--workers", type=positive_int, metavar="N",
                   help="batch worker processes (default: the usable cores)")
    p.add_argument("--threads-per-worker", type=positive_int, metavar="T",
                   help="threads per worker (default: cores // workers; 1 with --scheduler)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--dask", action="store_true",
                   help="run on a Dask LocalCluster of --workers processes")
    fit = p.add_argument_group("fit options (as `mcmcfit fit`; --force refits complete cases)")
    add_schedule_arguments(fit)
    p.set_defaults(func=run)


def _list(text: str, known, what: str) -> tuple:
    items = tuple(x.strip() for x in str(text).split(",") if x.strip())
    bad = [x for x in items if x not in known]
    if bad or not items:
        raise InputError(f"unknown {what} {', '.join(bad) or '(none given)'}; use "
                         f"{', '.join(known)}")
    if len(set(items)) != len(items):
        raise InputError(f"{what} listed twice: {text}")
    return items


def _detail(text: str) -> dict:
    from pipeline.synthetic.skin_detail import DETAIL_KINDS

    if text == "all":
        return {}
    if text == "none":
        return {k: False for k in DETAIL_KINDS} | {"strength": 0.0}
    on = _list(text, DETAIL_KINDS, "skin detail")
    return {k: k in on for k in DETAIL_KINDS}


def options_from_args(args: argparse.Namespace):
    """Check the options (nothing is written) and return the EvaluateOptions."""
    from mcmcfit.batch.worker_env import usable_cores
    from mcmcfit.evaluation.cases import MODEL_VARIANTS, check_scene_subjects
    from mcmcfit.evaluation.run import EvaluateOptions
    from pipeline.synthetic.scenes import SCENES, scene_spec

    scenes = _list(args.scenes, SCENES, "scene(s)")
    models = _list(args.models, MODEL_VARIANTS, "model(s)")
    if args.size < 32:
        raise InputError(f"--size must be at least 32 pixels, got {args.size}")
    if args.subjects < 2:
        raise InputError(f"--subjects must be at least 2, got {args.subjects}")
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0, got {args.seed}")
    if getattr(args, "model_colour", None) is not None:
        raise InputError("--model-colour is set per model by evaluate (intrinsic and "
                         "baked-gamma linear, baked srgb); leave it out")
    if args.scheduler and args.dask:
        raise InputError("give either --scheduler (a running cluster) or --dask (a local one)")
    check_scene_subjects({s: scene_spec(s) for s in scenes}, args.subjects, args.held_out)
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    cores = usable_cores()
    workers = args.workers or cores
    threads = args.threads_per_worker or (1 if args.scheduler else max(1, cores // workers))
    return EvaluateOptions(
        out=out, n_subjects=args.subjects, n_held_out=args.held_out, scenes=scenes,
        models=models, size=args.size, seed=args.seed, population_seed=args.population_seed,
        detail=_detail(args.detail), config=config_from_args(args), workers=workers,
        threads=threads, dask=args.dask, scheduler=args.scheduler,
        score_only=args.score_only, force=args.force, progress=not args.quiet)


def run(args: argparse.Namespace) -> int:
    """Run ``mcmcfit evaluate``; print the table; return 1 when a fit failed, else 0."""
    from mcmcfit.evaluation.run import run_evaluation

    opts = options_from_args(args)
    with cli_warnings("evaluate"):
        results = run_evaluation(opts)
    failed = sum(r.get("status") == "failed" for r in results["rows"])
    print((Path(opts.out) / "table.md").read_text(encoding="utf-8"))
    ok = sum(r.get("status") == "ok" for r in results["rows"])
    print(f"mcmcfit evaluate: {ok} fits scored, {failed} failed "
          f"-> {opts.out} (table.md, table.csv, calibration.png, accuracy_time.png, "
          "report.html, results.json)", file=sys.stderr)
    return 1 if failed else 0
