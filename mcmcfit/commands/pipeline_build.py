"""``mcmcfit pipeline build``: capture folder -> AlbedoMM model files.

Processes every subject (cached in a work folder, so a rerun resumes),
completes, models and evaluates the population (:mod:`pipeline.lightstage.build`).

This module imports :mod:`albedo_model.errors`; :mod:`pipeline.lightstage` (``build``,
``capture_folder``), :mod:`pipeline.texturing.capture_io` and
:mod:`pipeline.synthetic.albedo_preview` are imported when it runs.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from albedo_model.errors import InputError

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``build`` options to ``parser``."""
    parser.add_argument("captures", metavar="CAPTURES_DIR", type=Path,
                        help="capture folder (layout: pipeline/lightstage/capture_folder.py)")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="MODEL.h5",
                        help="model to write (transferred variant; the other variants, the "
                             "leave-one-out plot and a JSON report are written beside it)")
    parser.add_argument("--work-dir", type=Path, default=None, metavar="DIR",
                        help="per-subject results (default: MODEL.h5.work)")
    parser.add_argument("--rank", type=int, default=None, metavar="K",
                        help="components kept (default: all)")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), metavar="J",
                        help="worker processes (default: 2 or the number of CPUs)")
    parser.add_argument("--loo-components", type=int, default=None, metavar="K",
                        help="largest number of modes in the leave-one-out curves")
    parser.add_argument("--only-transferred", action="store_true",
                        help="do not write the independent and concatenated variants")
    parser.add_argument("--preview", type=Path, default=None, metavar="PNG",
                        help="picture of the first subject's recovered albedo (and its truth "
                             "when the captures are synthetic)")


def _preview(path: Path, report, captures: Path) -> None:
    import numpy as np

    from pipeline.lightstage.capture_folder import read_template
    from pipeline.synthetic.albedo_preview import write_albedo_preview
    from pipeline.texturing.capture_io import load_mesh

    template = read_template(captures)
    name = report.subjects[0]
    with np.load(report.files["maps"], allow_pickle=False) as z:
        i = list(z["names"]).index(name)
        diffuse, specular = z["diffuse"][i], z["specular"][i]
    truth_file = captures / "subjects" / name / "truth.npz"
    maps = []
    if truth_file.is_file():
        with np.load(truth_file, allow_pickle=False) as t:
            maps.append(("true diffuse", t["diffuse"], 1.0))
            maps.append(("recovered diffuse", diffuse, 1.0))
            maps.append(("true specular", t["specular"], 1.5))
            maps.append(("recovered specular", specular, 1.5))
    else:
        maps = [("diffuse", diffuse, 1.0), ("specular", specular, 1.5)]

    verts, _ = load_mesh(captures / "subjects" / name / "registered.ply")
    write_albedo_preview(path, verts, template.triangles, maps,
                         title=f"{name}: linear sRGB shown with gamma 2.2 (specular x1.5)")


def run(args: argparse.Namespace) -> int:
    """Build; print progress on stderr and a summary."""
    from pipeline.lightstage.build import BuildSettings, build_model

    if args.jobs < 1:
        raise InputError("--jobs must be >= 1")
    if not args.captures.is_dir():
        raise InputError(f"{args.captures}: capture folder not found")
    settings = BuildSettings(rank=args.rank, jobs=args.jobs, loo_components=args.loo_components,
                             variants=not args.only_transferred)
    start = time.perf_counter()

    def progress(name: str, done: int, total: int) -> None:
        print(f"[{done}/{total}] {name} ({time.perf_counter() - start:.0f} s)", file=sys.stderr,
              flush=True)

    report = build_model(args.captures, args.output, work_dir=args.work_dir, settings=settings,
                         progress=progress)
    print(f"built {args.output} from {len(report.subjects)} subjects and "
          f"{len(report.external)} external scans ({report.reused} reused) in "
          f"{report.seconds['total']:.0f} s")
    overall = report.accuracy.get("overall")
    if overall:
        print("albedo RMSE vs truth (linear sRGB, observed vertices): diffuse "
              f"{overall['diffuse']:.4f}, specular {overall['specular']:.4f} "
              f"(after completion {overall['diffuse_final']:.4f}, "
              f"{overall['specular_final']:.4f})")
    gen = report.generalisation
    k = gen["components"]
    picks = [i for i in (1, 5, 10, 20, 40) if i < len(k)] + [len(k) - 1]
    for v, curve in gen["fit_mean"].items():
        print(f"leave-one-out specular error, {v}: " +
              ", ".join(f"{k[i]} modes {curve[i]:.4f}" for i in sorted(set(picks))))
    for role, path in report.files.items():
        print(f"  {role}: {path}")
    if args.preview is not None:
        _preview(args.preview, report, args.captures)
        print(f"  preview: {args.preview}")
    return 0
