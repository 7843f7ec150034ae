"""``mcmcfit batch`` (fit a folder of images) and ``mcmcfit batch-report`` (summarise a batch).

This module imports :mod:`albedo_model.errors` and :mod:`mcmcfit.commands.fit`;
:mod:`mcmcfit.batch` and :mod:`mcmcfit.jobs` modules are imported when a command runs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from albedo_model.errors import InputError
from mcmcfit.commands.fit import add_schedule_arguments, config_from_args

__all__ = ["positive_int", "register", "run_batch_command", "run_report_command"]

_BATCH_HELP = """\
Fit every image of INPUT (a folder walked recursively for .jpg/.jpeg/.png, or a
text file listing one image per line) and write each image's results to
OUT/<relative path without extension>/, exactly as `mcmcfit fit` writes them.

Landmarks: beside each image (<stem>.tlms, then <stem>.pts), or under
--landmarks-dir (a tree parallel to INPUT), or --landmarks-glob (placeholders
{stem} {name} {rel} {parent}, relative to the image's folder). Images without
landmarks are skipped (recorded in OUT/failures.jsonl with the reason) unless
--detect-landmarks is given (MediaPipe Face Mesh, the optional extra
mcmcfit[landmarks]; the detected points are written into each result folder),
or --face-box-default: then they are fitted with LFW's face box, the
central square of side 1/2.2 of the image ((68.2, 68.2)-(181.8, 181.8) in a
250x250 LFW crop: LFW enlarged the detected face 2.2x before cropping), or
with --face-box x,y,w,h.

Each result folder appears complete or not at all; re-running the command skips
complete images (a folder with summary.json) and redoes the others; --force
refits everything. Failures go to OUT/failures.jsonl and the batch continues;
finished images to OUT/batch.jsonl. Exit code 1 when an image failed.

--group-by person fits the photographs of each person jointly (one identity,
each photograph its own pose, camera, expression and light; as `mcmcfit fit
IMG1 IMG2 ...`) into OUT/<person>/: a person is the image's folder relative to
INPUT (LFW: Name/Name_0001.jpg), or for an image at the top of INPUT its stem
without a trailing _<number>. At most --max-per-person photographs per person
(default 4, the first in sorted order; the rest are recorded as skipped); a
person with one usable photograph gets a single fit. It needs landmarks (files
or --detect-landmarks), not a face box.

Parallelism: a local process pool (--workers, default: the cores), or Dask:
--scheduler tcp://host:8786 sends one task per image to a running cluster
(INPUT, landmarks, model and OUT must be on storage the workers share under the
same paths; the workers write the result folders), --dask starts a LocalCluster
of --workers processes. Image seeds derive from --seed and the relative path,
so every engine gives the same numbers.
"""


def positive_int(text: str) -> int:
    """Parse a command-line integer >= 1 (an ``argparse`` type)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


def register(subparsers) -> None:
    """Add the ``batch`` and ``batch-report`` commands."""
    p = subparsers.add_parser(
        "batch", help="fit every image of a folder (resumable, parallel, Dask)",
        description=_BATCH_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("input", help="folder of images, or a text file listing images")
    p.add_argument("-o", "--output", required=True, help="output folder OUT")
    lm = p.add_mutually_exclusive_group()
    lm.add_argument("--landmarks-dir", metavar="DIR", help="landmark tree parallel to INPUT")
    lm.add_argument("--landmarks-glob", metavar="PATTERN",
                    help="landmark file pattern, e.g. '../landmarks/{stem}*.pts'")
    box = p.add_mutually_exclusive_group()
    box.add_argument("--detect-landmarks", action="store_true",
                     help="detect the landmarks of images without landmark files "
                     "(needs mcmcfit[landmarks])")
    box.add_argument("--face-box-default", action="store_true",
                     help="fit images without landmarks with the LFW face box (see above)")
    box.add_argument("--face-box", metavar="X,Y,W,H",
                     help="fit images without landmarks with this face box (pixels)")
    p.add_argument("--group-by", choices=["person"], dest="group_by",
                   help="fit each person's photographs jointly (see above)")
    p.add_argument("--max-per-person", type=positive_int, default=4, metavar="N",
                   help="with --group-by person: photographs fitted together, 2-8 (default 4)")
    p.add_argument("--model", default="default-face",
                   help="model file (.h5), 'default-face' (default: the face-only crop of the "
                   "built-in model) or 'default' (the whole head)")
    p.add_argument("--workers", type=positive_int, metavar="N",
                   help="worker processes (default: the usable cores)")
    p.add_argument("--threads-per-worker", type=positive_int, metavar="T",
                   help="threads per worker (default: cores // workers, at least 1; "
                   "1 with --scheduler)")
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--dask", action="store_true",
                   help="run on a Dask LocalCluster of --workers processes")
    p.add_argument("--pin", action="store_true",
                   help="pin each pool worker to one core (the only limit that also bounds XLA "
                   "and Embree; slower when other processes share the cores)")
    fit = p.add_argument_group("fit options (as `mcmcfit fit`; --force refits complete images, "
                               "--quiet hides the progress bar; each image's seed derives "
                               "from --seed and its relative path)")
    add_schedule_arguments(fit)
    p.set_defaults(func=run_batch_command)

    r = subparsers.add_parser(
        "batch-report", help="HTML table and plots over a batch, and a CSV",
        description="Summarise a batch folder: time per image, acceptance, landmark error, "
        "mean albedo per subject (LFW: the top-level folder), failures; one HTML page with "
        "the plots embedded, and optionally a CSV with one row per image.")
    r.add_argument("out", help="the batch's output folder")
    r.add_argument("-o", "--output", required=True, help="HTML file to write")
    r.add_argument("--csv", metavar="FILE", help="also write one CSV row per image")
    r.set_defaults(func=run_report_command)


def run_batch_command(args: argparse.Namespace) -> int:
    """Run ``mcmcfit batch``: check the options, fit the images, print a summary.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``batch`` options.

    Returns
    -------
    int
        The exit code: 1 when an image failed in this run, else 0.
    """
    from mcmcfit.batch.run import BatchOptions, run_batch
    from mcmcfit.batch.task import LFW_BOX
    from mcmcfit.batch.worker_env import usable_cores
    from mcmcfit.jobs.model_spec import resolve_model

    src = Path(args.input)
    if not src.exists():
        raise InputError(f"{src}: input folder or list file not found")
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0, got {args.seed}")
    if args.scheduler and args.dask:
        raise InputError("give either --scheduler (a running cluster) or --dask (a local one)")
    face_box = None
    if args.detect_landmarks:
        from mcmcfit.batch.task import DETECT
        from mcmcfit.detection.face_mesh import INSTALL_HINT, available

        if not available():  # one clear error, not one failure per image
            raise InputError(INSTALL_HINT)
        face_box = DETECT
    elif args.face_box_default:
        face_box = LFW_BOX
    elif args.face_box:
        from mcmcfit.jobs.fit_job import parse_face_box

        parse_face_box(args.face_box)  # validate now, not once per image
        face_box = args.face_box
    if args.landmarks_dir and not Path(args.landmarks_dir).is_dir():
        raise InputError(f"{args.landmarks_dir}: landmarks folder not found")
    cores = usable_cores()
    workers = args.workers or cores
    # this machine's cores say nothing about a remote cluster's workers: one thread there
    threads = args.threads_per_worker or (1 if args.scheduler else max(1, cores // workers))
    # a missing model is one clear error, not N failures; "default" is built once, here
    resolve_model(args.model)
    opts = BatchOptions(input=src, out=Path(args.output), model=args.model,
                        config=config_from_args(args),
                        seed=args.seed, landmarks_dir=args.landmarks_dir,
                        landmarks_glob=args.landmarks_glob, face_box=face_box, force=args.force,
                        workers=workers, threads=threads, scheduler=args.scheduler,
                        dask=args.dask, pin=args.pin and not (args.scheduler or args.dask),
                        progress=not args.quiet, model_colour=args.model_colour,
                        group_by=args.group_by, max_per_person=args.max_per_person)
    result = run_batch(opts)
    unit = "people" if args.group_by else "images"
    print(f"mcmcfit batch: {result.fitted}{' people' if args.group_by else ''} fitted, "
          f"{len(result.failed)} failed, "
          f"{result.already_complete} already complete, {result.skipped} skipped "
          f"-> {opts.out}", file=sys.stderr)
    if result.unconverged:
        print(f"mcmcfit batch: warning: {result.unconverged} of the {result.fitted} fitted {unit} "
              "have NOT converged ('converged': false in their summary.json and in batch.jsonl; "
              "see the banner of their report.html)", file=sys.stderr)
    for f in result.failed[:10]:
        print(f"  failed: {f.get('path')}: {f.get('reason')}", file=sys.stderr)
    if len(result.failed) > 10:
        print(f"  ... {len(result.failed) - 10} more in {opts.out / 'failures.jsonl'}",
              file=sys.stderr)
    return result.exit_code


def run_report_command(args: argparse.Namespace) -> int:
    """Run ``mcmcfit batch-report``: write the HTML page (and the CSV) of a batch folder.

    Returns
    -------
    int
        The exit code, 0.
    """
    from mcmcfit.batch.report import write_batch_report

    out = Path(args.out)
    if not out.is_dir():
        raise InputError(f"{out}: batch folder not found")
    rows = write_batch_report(out, args.output, csv_path=args.csv)
    print(f"wrote {args.output} ({rows} images)" + (f" and {args.csv}" if args.csv else ""))
    return 0
