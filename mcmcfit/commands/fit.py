"""``mcmcfit fit IMAGE -o OUT``: fit one photograph and write its result folder.

This module imports :mod:`albedo_model.errors`, :mod:`mcmcfit.fitting.config`,
:mod:`mcmcfit.fitting.progress` and :mod:`mcmcfit.jobs.fit_job`, all inside
functions (building the command-line parser must not load JAX).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import warnings
from pathlib import Path

__all__ = ["register", "run", "add_schedule_arguments", "config_from_args", "cli_warnings"]


def add_schedule_arguments(p: argparse.ArgumentParser, *, steps_default: str = "10000",
                           landmark_default: str = "5000", chains_default: str = "2") -> None:
    """Options of the sampling schedule and the output (shared with ``mcmcfit demo``).

    The defaults shown are FitConfig's (not imported here: it loads JAX, and every CLI
    start builds this parser); ``test_cli_fit`` checks that they agree.
    """
    p.add_argument("--max-steps", "--steps", dest="steps", type=int, metavar="N",
                   help="most kept image-stage steps per chain; the fit stops earlier once "
                   f"the chains have converged (default {steps_default})")
    p.add_argument("--warmup-steps", type=int, metavar="N",
                   help="image-stage warm-up steps per chain: step sizes adapted, never part "
                   "of the posterior (default 500 after the climb to the mode; 30%% of "
                   "--max-steps with --sampler random-walk)")
    p.add_argument("--sampler", choices=("gaussian", "random-walk"),
                   help="image stage: climb to the mode, fixed interior pixel region, moves "
                   "from the posterior's Laplace approximation and exact conditionals "
                   "(gaussian, the default), or the previous random walks over the pixels the "
                   "render covers (random-walk)")
    p.add_argument("--time-budget", type=float, metavar="SECONDS",
                   help="start no further round of kept draws after this many seconds "
                   "(the fit then says whether it converged)")
    p.add_argument("--landmark-steps", type=int, metavar="N",
                   help=f"landmark-stage steps per chain (default {landmark_default})")
    p.add_argument("--chains", type=int, metavar="K",
                   help=f"independent chains (default {chains_default}), run in parallel "
                   "processes: as many as cores")
    p.add_argument("--serial", action="store_true",
                   help="run the chains one after the other in this process (same chains)")
    p.add_argument("--noise", choices=("estimated", "fixed"),
                   help="image likelihood scale: measured per image from the residuals "
                   "(default) or the configured sigma_px and temperature")
    p.add_argument("--model-colour", choices=("linear", "srgb"),
                   help="the model's colour space: linear albedo (AlbedoMM, the built-in "
                   "models) or a gamma-encoded sRGB texture (BFM 2017), compared with the "
                   "photograph's encoded values and reported decoded to linear (default: "
                   "read from the model file, else by its layout)")
    p.add_argument("--effects", choices=("auto", "sh", "sh+directional"),
                   help="the light of the fit's image model: the SH light alone (sh), plus "
                   "one sampled directional light with cast shadows (sh+directional), or "
                   "decided per photograph from how much the directional light improves "
                   "the fit at the mode (auto, the default; recorded in summary.json)")
    p.add_argument("--soft-shadows", type=int, metavar="K", dest="shadow_rays",
                   help="shadow rays per face pixel over a light of 3 degrees radius when the "
                   "directional light is on: soft shadow edges at K times the shadow rays "
                   "(default 1: hard shadows)")
    p.add_argument("--foreground", choices=("gaussian", "robust"),
                   help="the image likelihood: every face pixel Gaussian around the render "
                   "(default), or robust: each pixel the face or, with a probability measured "
                   "per photograph, something the model cannot explain (hair, glasses, a hand)")
    p.add_argument("--seed", type=int, default=0, help="root seed of the fit (default 0)")
    p.add_argument("--config", metavar="F.json",
                   help="fit settings as JSON (a config.json of an earlier fit); "
                   "the schedule options override it")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--check-cache", action="store_true",
                   help="debug: after every step compare every cached product (render, log "
                        "densities, proposal data) with a fresh computation; stops with an "
                        "error naming the first difference (several times slower)")


def config_from_args(args: argparse.Namespace, **defaults):
    """Build the FitConfig of ``--config`` (or the defaults) with the schedule options applied."""
    from albedo_model.errors import InputError
    from mcmcfit.fitting.config import FitConfig

    if args.config:
        path = Path(args.config)
        if not path.is_file():
            raise InputError(f"{path}: config file not found")
        try:
            cfg = FitConfig.from_json(path.read_text(encoding="utf-8"))
        except ValueError as exc:
            raise InputError(f"{path}: not a fit config ({exc})") from None
    else:
        cfg = FitConfig(**defaults)
    options = (("steps", args.steps), ("landmark_steps", args.landmark_steps),
               ("chains", args.chains), ("warmup_steps", getattr(args, "warmup_steps", None)),
               ("time_budget", getattr(args, "time_budget", None)),
               ("noise", getattr(args, "noise", None)),
               ("sampler", getattr(args, "sampler", None)),
               ("model_colour", getattr(args, "model_colour", None)),
               ("effects", getattr(args, "effects", None)),
               ("shadow_rays", getattr(args, "shadow_rays", None)),
               ("foreground", getattr(args, "foreground", None)))
    changes = {k: v for k, v in options if v is not None}
    if getattr(args, "serial", False):
        changes["parallel"] = False
    if getattr(args, "check_cache", False):
        changes["check_cache"] = True
    return cfg.replace(**changes) if changes else cfg


@contextlib.contextmanager
def cli_warnings(command: str):
    """Show the project's own warnings as one line each: ``mcmcfit CMD: warning: ...``.

    Warnings raised in the project's packages (e.g. landmark names the model does
    not know) are for the user; those of libraries keep Python's format.
    """
    from mcmcfit.jobs.fit_job import FitWarning

    original = warnings.showwarning
    root = Path(__file__).resolve().parents[2]
    ours = tuple(str(root / pkg) for pkg in ("mcmcfit", "albedo_model", "proposals", "pipeline"))

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, FitWarning) or (
                issubclass(category, UserWarning) and str(filename).startswith(ours)):
            print(f"mcmcfit {command}: warning: {message}", file=sys.stderr)
        else:
            original(message, category, filename, lineno, file, line)

    with warnings.catch_warnings():
        warnings.simplefilter("always", FitWarning)
        warnings.filterwarnings("always", category=UserWarning,
                                module=r"(mcmcfit|albedo_model|proposals|pipeline)(\.|$)")
        warnings.showwarning = show
        yield


def register(subparsers) -> None:
    """Add the ``fit`` command."""
    p = subparsers.add_parser(
        "fit", help="fit a face image: posterior albedo, uncertainty, report",
        description="Fit the morphable albedo model to one photograph (landmark stage, then "
        "image stage, for several chains) and write a result folder: posterior.npz, best.rps, "
        "mean.rps, fit.png, albedo and uncertainty maps, mesh.ply, chain.h5, summary.json, "
        "report.html. The folder appears complete or not at all. Several photographs of one "
        "person are fitted jointly into one folder (one shape and albedo; image<k>/ per "
        "photograph); give them before the options: mcmcfit fit A.png B.png --landmarks "
        "A.tlms B.tlms -o OUT.",
    )
    p.add_argument("image", nargs="+",
                   help="photograph (PNG or JPEG, sRGB); several photographs of one person are "
                   "fitted jointly: one shape and albedo, each its own pose, camera, expression "
                   "and light")
    p.add_argument("--landmarks", metavar="F.tlms|F.pts", nargs="+",
                   help="2-D landmarks, one file per photograph in the same order: TLMS (Basel "
                   "names) or iBUG 68-point .pts (default: detected with MediaPipe Face Mesh, "
                   "the optional extra mcmcfit[landmarks])")
    p.add_argument("--face-box", metavar="x,y,w,h",
                   help="face box in pixels, used instead of landmarks")
    p.add_argument("--face", type=int, default=None, metavar="N",
                   help="with detected landmarks: which face, by size (0: the largest)")
    p.add_argument("--model", default="default-face",
                   help="model file (.h5), 'default-face' (default: the face-only crop of the "
                   "built-in model) or 'default' (the whole head)")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="result folder to create")
    add_schedule_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``mcmcfit fit`` and print where the result went; return the exit code."""
    from albedo_model.errors import InputError
    from mcmcfit.fitting.progress import FitProgressBar
    from mcmcfit.jobs.fit_job import run_fit_job

    cfg = config_from_args(args)
    out = Path(args.output)
    if args.landmarks is not None and len(args.landmarks) != len(args.image):
        raise InputError(f"{len(args.image)} photograph(s) but {len(args.landmarks)} landmark "
                         "file(s): give one per photograph, in the same order")
    if len(args.image) > 1 and args.face_box is not None:
        raise InputError("a joint fit of several photographs needs landmarks, not --face-box")
    with cli_warnings("fit"), FitProgressBar(cfg.chains, disable=args.quiet) as bar:
        if len(args.image) > 1:
            from mcmcfit.jobs.joint_job import run_joint_fit_job

            summary = run_joint_fit_job(args.image, out, landmarks_paths=args.landmarks,
                                        model=args.model, config=cfg, seed=args.seed,
                                        progress=bar, force=args.force,
                                        model_progress=not args.quiet, face=args.face)
        else:
            summary = run_fit_job(args.image[0], out, landmarks_path=args.landmarks[0]
                                  if args.landmarks else None, face_box=args.face_box,
                                  model=args.model, config=cfg, seed=args.seed, progress=bar,
                                  force=args.force, model_progress=not args.quiet,
                                  face=args.face)
    print(_done_line(out, summary))
    return 0


def _done_line(out: Path, summary: dict) -> str:
    t = summary.get("timings", {})
    rmse = summary.get("landmark_rmse_px")
    lm = f", landmark RMSE {rmse:.2f} px" if rmse is not None else ""
    where = (f"open {out / 'report.html'}" if "report.html" in summary.get("files", [])
             else f"{len(summary.get('images', []))} photographs fitted jointly")
    return (f"wrote {out}/ ({len(summary.get('files', []))} files; fit {t.get('total_s', 0):.1f} s"
            f"{lm}); {where}")
