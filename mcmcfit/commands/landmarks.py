"""``mcmcfit landmarks``: Basel-named landmarks detected in a photograph (MediaPipe Face Mesh).

This module imports :mod:`albedo_model.io` (image, tlms) and :mod:`mcmcfit.detection`
when it runs; registering it imports nothing heavy.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

__all__ = ["register", "run"]


def register(subparsers) -> None:
    """Add the ``landmarks`` command."""
    p = subparsers.add_parser(
        "landmarks", help="detect Basel-named landmarks in a photograph (needs mcmcfit[landmarks])",
        description="Detect a face with MediaPipe Face Mesh (shipped in the optional extra "
        "mcmcfit[landmarks]; nothing is downloaded) and write its Basel-named landmarks as a "
        ".tlms file, which `mcmcfit fit --landmarks` reads. Near profile the points of the side "
        "turned away are dropped and the detection is flagged.",
    )
    p.add_argument("image", help="photograph (PNG or JPEG)")
    p.add_argument("-o", "--output", metavar="F.tlms",
                   help="landmark file to write (default: print the points)")
    p.add_argument("--png", metavar="overlay.png", help="picture of the points over the photo")
    p.add_argument("--face", type=int, default=None, metavar="N",
                   help="which face when there are several, by size (0: the largest, default)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``mcmcfit landmarks``; return the exit code."""
    from albedo_model.errors import InputError
    from albedo_model.io.image_io import read_image
    from albedo_model.io.tlms import write_tlms
    from mcmcfit.detection.landmarks import detect_landmarks
    from mcmcfit.detection.overlay import landmarks_png

    out = Path(args.output) if args.output else None
    if out is not None and out.suffix.lower() != ".tlms":
        raise InputError(f"{out}: the landmark file must end in .tlms")
    image = read_image(args.image)
    t0 = time.perf_counter()
    found = detect_landmarks(image, face=args.face)
    seconds = time.perf_counter() - t0
    if out is not None:
        write_tlms(out, found.landmarks)
    if args.png:
        landmarks_png(image, found.points(), args.png, mesh=found.mesh, box=found.box,
                      title=f"{Path(args.image).name}: face {found.face} of {found.n_faces}, "
                            f"yaw {found.yaw_deg:+.0f} deg")
    flag = "; LOW CONFIDENCE (near profile): check the points" if found.low_confidence else ""
    dropped = f", {len(found.dropped)} far-side points dropped" if found.dropped else ""
    print(f"{len(found.landmarks)} landmarks of face {found.face} ({found.n_faces} found), "
          f"yaw {found.yaw_deg:+.1f} deg{dropped}, {seconds:.2f} s{flag}"
          + (f" -> {out}" if out is not None else ""))
    if out is None:
        for lm in found.landmarks:
            print(f"{lm.name} {lm.point[0]:.1f} {lm.point[1]:.1f}")
    return 0
