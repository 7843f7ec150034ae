"""``mcmcfit pipeline ACTION``: lightstage processing steps.

Actions: ``stitch`` (sample calibrated photographs onto a registered mesh and
blend them into one seamless per-vertex texture by screened-Poisson
stitching), ``simulate`` (write synthetic lightstage captures) and ``build``
(capture folder -> albedo model). Further actions register by appending a
``register_<action>(actions)`` function to :data:`ACTIONS`.

This module imports :mod:`mcmcfit.commands.subcommands` when it loads; :mod:`albedo_model`
(``errors``, ``io.image_io``), :mod:`pipeline.texturing` (``stitch_capture``,
``texture_preview``), :mod:`mcmcfit.commands.pipeline_simulate` and
:mod:`mcmcfit.commands.pipeline_build` are imported when an action registers or runs.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mcmcfit.commands.subcommands import add_action

__all__ = ["ACTIONS", "register"]


def _run_stitch(args: argparse.Namespace) -> int:
    from albedo_model.errors import InputError
    from albedo_model.io.image_io import write_png
    from pipeline.texturing.stitch_capture import stitch_capture, write_texture
    from pipeline.texturing.texture_preview import stitch_preview

    if args.reference_view is not None and args.reference_view < 1:
        raise InputError(f"--reference-view counts from 1, got {args.reference_view}")
    if args.mask_scale < 1 or args.preview_scale < 1:
        raise InputError("--mask-scale and --preview-scale must be positive integers")
    run = stitch_capture(
        args.mesh, args.views, args.cameras, lam=args.lam,
        boundary_distance_px=args.boundary_distance,
        reference_view=None if args.reference_view is None else args.reference_view - 1,
        reference_region=args.reference_region, no_view_weight=args.no_view_weight,
        mask_scale=args.mask_scale,
    )
    write_texture(args.output, run)
    sel = run.result.selected_view
    per_view = ", ".join(f"view {i + 1} {int((sel == i).sum())}" for i in range(len(run.views)))
    t = run.timings
    print(f"wrote {args.output}: {len(run.vertices)} vertices, {len(run.views)} views, "
          f"reference view {run.settings.reference_view + 1}, lambda {run.settings.lam:g}, "
          f"no-view weight {run.no_view_weight:g}")
    print(f"triangles: {per_view}, none {int((sel < 0).sum())}; "
          f"relative residual {run.result.residual:.2g}")
    print("seconds: " + ", ".join(f"{k} {v:.2f}" for k, v in t.items()))
    if args.png is not None:
        picture = stitch_preview(run.images, run.cameras, run.vertices, run.triangles,
                                 np.clip(run.result.colour, 0.0, 1.0), sel,
                                 factor=args.preview_scale)
        write_png(args.png, picture)
        print(f"wrote {args.png}")
    return 0


def register_stitch(actions: argparse._SubParsersAction) -> None:
    """Add ``pipeline stitch``."""
    p = add_action(
        actions, "stitch", _run_stitch,
        help="blend calibrated photographs into one per-vertex texture",
        description="Samples each photograph onto the registered mesh (visibility, cosine "
                    "weights, silhouette margin), picks the best view per triangle and solves "
                    "a screened Poisson equation for seamless per-vertex colours "
                    "(AlbedoMM, Sec. 3.3). Stitching settings default to the camera file's.",
    )
    p.add_argument("mesh", metavar="MESH", type=Path,
                   help="registered mesh: PLY/OBJ, or .mat with V and 1-based F")
    p.add_argument("views", metavar="VIEWS", type=Path, nargs="+",
                   help="photographs, in the order of the camera file's views")
    p.add_argument("--cameras", required=True, type=Path,
                   help="camera file (JSON: intrinsics, per-view extrinsics T, stitching)")
    p.add_argument("-o", "--output", required=True, type=Path, help="texture file to write (.npz)")
    p.add_argument("--png", type=Path, help="also write a preview picture (photos vs texture)")
    p.add_argument("--lambda", dest="lam", type=float, help="screening weight (paper: 0.1)")
    p.add_argument("--boundary-distance", type=float, metavar="PX",
                   help="silhouette margin in pixels (paper demo: 100)")
    p.add_argument("--reference-view", type=int, metavar="I",
                   help="1-based view that fixes the colour offset (default: camera file's)")
    p.add_argument("--reference-region", choices=("valid", "selected"), default="valid",
                   help="screen all valid reference vertices (published code) or only those "
                        "where the reference view is best (paper text)")
    p.add_argument("--no-view-weight", type=float, default=0.01, metavar="W",
                   help="weight of the zero-gradient rows of triangles no view sees (default "
                        "0.01; 1 reproduces the published implementation)")
    p.add_argument("--mask-scale", type=int, default=4,
                   help="silhouette raster reduction factor (default 4)")
    p.add_argument("--preview-scale", type=int, default=4,
                   help="size reduction of the preview picture (default 4)")


def register_simulate(actions: argparse._SubParsersAction) -> None:
    """Add ``pipeline simulate``."""
    from mcmcfit.commands import pipeline_simulate

    add_action(
        actions, "simulate", pipeline_simulate.run, arguments=pipeline_simulate.add_arguments,
        help="write simulated lightstage captures of synthetic subjects",
        description="Synthetic subjects in a polarised 41-LED lightstage: three poses, "
                    "parallel/perpendicular photometric pairs, 7 unpolarised views, spectral "
                    "camera, ISO, sensor noise, misalignment; every effect can be switched off.",
    )


def register_build(actions: argparse._SubParsersAction) -> None:
    """Add ``pipeline build``."""
    from mcmcfit.commands import pipeline_build

    add_action(
        actions, "build", pipeline_build.run, arguments=pipeline_build.add_arguments,
        help="build an albedo model (AlbedoMM HDF5) from a capture folder",
        description="Polarisation separation, intrinsic albedo, calibrated colour, per-view "
                    "sampling, stitching, inpainting, external scans, symmetry-augmented PCA "
                    "(three variants) and their leave-one-out comparison. Resumable.",
    )


#: One registrar per ``pipeline`` action, in help order.
ACTIONS: list[Callable[[argparse._SubParsersAction], None]] = [
    register_stitch, register_simulate, register_build,
]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``pipeline`` command group and its actions."""
    parser = subparsers.add_parser("pipeline", help="lightstage processing steps")
    actions = parser.add_subparsers(dest="pipeline_action", metavar="ACTION", required=True)
    for add in ACTIONS:
        add(actions)
