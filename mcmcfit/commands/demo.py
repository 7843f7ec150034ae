"""``mcmcfit demo``: fit a synthetic face with known truth and report the albedo error.

This module imports :mod:`mcmcfit.commands.fit`; :mod:`albedo_model.io`,
:mod:`mcmcfit.fitting.progress`, :mod:`mcmcfit.jobs` and :mod:`mcmcfit.outputs.truth`
are imported when a demo runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from mcmcfit.commands.fit import add_schedule_arguments, cli_warnings, config_from_args

__all__ = ["register", "run", "run_demo"]


def register(subparsers) -> None:
    """Add the ``demo`` command."""
    p = subparsers.add_parser(
        "demo", help="fit a synthetic face of the default model and compare with the truth",
        description="Render a random face of the built-in default model (known coefficients, "
        "pose and light) over a textured background, save it with its truth (target.png, "
        "truth.rps, landmarks.tlms), fit it, write the result folder and report, and print the "
        "error of the posterior-mean diffuse albedo against the true albedo (RMSE on the "
        "vertices visible in the true view, linear sRGB) with the coverage of the 90 %% "
        "intervals: posterior predictive (with the model's residual variance, when it has one) "
        "and coefficient-only. The face is drawn from the model, inside its span: the "
        "coefficient-only coverage is the one to compare with 90 %%.",
    )
    p.add_argument("-o", "--output", default="mcmcfit-demo", metavar="OUT",
                   help="result folder to create (default ./mcmcfit-demo)")
    p.add_argument("--size", type=int, default=250, metavar="PX",
                   help="width and height of the synthetic image (default 250)")
    p.add_argument("--case-seed", type=int, default=None, metavar="S",
                   help="seed of the synthetic face (default: --seed)")
    p.add_argument("--model", default="default", help="model file (.h5) or 'default'")
    add_schedule_arguments(p)
    p.set_defaults(func=run)


def run_demo(out_dir, *, model="default", size: int = 250, case_seed: int = 0, seed: int = 0,
             config=None, progress=None, force: bool = False) -> dict:
    """Render a synthetic case, fit it into ``out_dir`` and return the summary (with ``truth``).

    Parameters
    ----------
    out_dir : path-like
        Result folder (written atomically; also holds ``truth.rps`` and ``landmarks.tlms``).
    model : str, path-like or LoadedModel
    size : int
        Image width and height.
    case_seed : int
        Seed of :func:`mcmcfit.jobs.synthetic_case.synthetic_case`.
    seed : int
        Seed of the fit.
    config : FitConfig, optional
    progress : callable ``(stage, chain, done, total)``, optional
    force : bool

    Returns
    -------
    dict
        ``summary.json``; ``summary["truth"]`` holds the albedo RMSE and coverage.
    """
    from albedo_model.io.rps import write_rps
    from albedo_model.io.tlms import Landmark, write_tlms
    from mcmcfit.jobs.fit_job import _as_loaded, _check_out_dir, fit_into_folder
    from mcmcfit.outputs.truth import Truth
    from mcmcfit.jobs.synthetic_case import synthetic_case

    out = Path(out_dir)
    _check_out_dir(out, force)
    loaded = _as_loaded(model)
    case = synthetic_case(loaded.model, seed=case_seed, size=size)
    truth_params = case.truth._replace(momo=case.truth.momo._replace(model_uri=loaded.uri))

    def save_truth(folder: Path) -> None:
        write_rps(folder / "truth.rps", truth_params)
        write_tlms(folder / "landmarks.tlms",
                   [Landmark(n, (float(p[0]), float(p[1])), True)
                    for n, p in case.landmarks.items()])

    inputs = {"image": "synthetic (target.png)", "landmarks": "landmarks.tlms",
              "image_size": [size, size], "case_seed": case_seed,
              "truth": "truth.rps"}
    truth = Truth(case.diffuse, case.specular, case.visible, case.truth)
    return fit_into_folder(case.image, case.landmarks, loaded, out, config=config, seed=seed,
                           progress=progress, force=force, inputs=inputs, truth=truth,
                           before_write=save_truth)


def run(args: argparse.Namespace) -> int:
    """Run ``mcmcfit demo`` (:func:`run_demo`) and print the result; return the exit code."""
    from mcmcfit.jobs.fit_job import load_model_cached
    from mcmcfit.fitting.progress import FitProgressBar

    cfg = config_from_args(args)
    out = Path(args.output)
    from mcmcfit.jobs.fit_job import _check_out_dir

    _check_out_dir(out, args.force)
    loaded = load_model_cached(args.model, progress=not args.quiet)
    case_seed = args.seed if args.case_seed is None else args.case_seed
    with cli_warnings("demo"), FitProgressBar(cfg.chains, disable=args.quiet) as bar:
        summary = run_demo(out, model=loaded, size=args.size, case_seed=case_seed,
                           seed=args.seed, config=cfg, progress=bar, force=args.force)
    print(format_demo_result(out, summary))
    return 0


def _pct(v) -> str:
    return "nan" if v is None else f"{100 * v:.1f} %"


def _coverage(e: dict) -> str:
    """Name the coverage printed: predictive and coefficient-only, or what the summary has."""
    if "coverage_coefficients" not in e:  # a summary without the split: its own intervals
        return _pct(e["coverage"])
    coef = f"coefficients only {_pct(e['coverage_coefficients'])}"
    if e.get("predictive"):
        return f"predictive {_pct(e['coverage_predictive'])}, {coef}"
    return f"{coef} (the model has no residual variance)"


def format_demo_result(out: Path, summary: dict) -> str:
    """Format the lines ``mcmcfit demo`` prints: albedo error, coverage, pose error, time.

    The coverage line names its intervals: posterior predictive (coefficients +
    the model's residual variance) and coefficient-only. The demo's face is
    drawn from the model, inside its span, so the coefficient-only coverage is
    the one its nominal level applies to; the predictive one is then higher.
    """
    truth = summary["truth"]
    level = 100 * truth["interval"]
    lines = [f"wrote {out}/ (open {out / 'report.html'})"]
    for part in ("diffuse", "specular"):
        if part in truth:
            e = truth[part]
            rmse = "nan" if e["rmse"] is None else f"{e['rmse']:.4f}"
            lines.append(f"{part} albedo: RMSE {rmse} (linear sRGB, {truth['n_visible']} visible "
                         f"vertices), coverage of the {level:.0f} % intervals: {_coverage(e)}")
    pe = truth.get("pose_error_deg")
    if pe:
        lines.append(f"pose error: yaw {pe['yaw']:.2f} deg, pitch {pe['pitch']:.2f} deg, "
                     f"roll {pe['roll']:.2f} deg")
    t = summary["timings"]
    lines.append(f"time: fit {t['total_s']:.1f} s (landmark stage {t['stage1_s']:.1f} s, "
                 f"image stage {t['stage2_s']:.1f} s, summed over chains)")
    return "\n".join(lines)
