"""``mcmcfit pipeline simulate``: write simulated lightstage captures (a capture folder).

Every effect of the capture simulator is on by default and can be switched
off (``--no-noise``, ``--no-specular`` ...); see :mod:`pipeline.synthetic.capture`
and the folder layout in :mod:`pipeline.lightstage.capture_folder`.

This module imports :mod:`albedo_model.errors`; :mod:`pipeline.synthetic.capture` and
:mod:`pipeline.synthetic.write_captures` are imported when it runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

from albedo_model.errors import InputError

__all__ = ["add_arguments", "run"]

_EFFECTS = ("specular", "shadows", "iso_gain", "noise", "misalignment", "multiview",
            "distortion")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``simulate`` options to ``parser``."""
    parser.add_argument("--subjects", type=int, required=True, metavar="N",
                        help="number of captured subjects")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="CAPTURES_DIR",
                        help="capture folder to write (created; finished subjects are kept)")
    parser.add_argument("--external", type=int, default=0, metavar="K",
                        help="also write K 3DRFE-like single-view external scans (default 0)")
    parser.add_argument("--seed", type=int, default=0, help="population seed (default 0)")
    parser.add_argument("--resolution", type=int, default=512, metavar="PX",
                        help="photometric image size (square, default 512)")
    parser.add_argument("--extra-resolution", type=int, default=384, metavar="PX",
                        help="size of the 7 unpolarised views (default 384)")
    parser.add_argument("--camera", default=None, metavar="NAME_OR_CSV",
                        help="camera sensitivities: a colour-science name (default "
                             "'Nikon 5100 (NPL)') or a 'lambda,R,G,B' CSV file")
    parser.add_argument("--illuminant", default="LED-B4",
                        help="LED spectrum, a colour-science illuminant (default LED-B4)")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), metavar="J",
                        help="worker processes (default: 2 or the number of CPUs)")
    for name in _EFFECTS:
        flag = name.replace("_", "-")
        parser.add_argument(f"--no-{flag}", dest=f"no_{name}", action="store_true",
                            help=f"switch the {name.replace('_', ' ')} effect off")


def run(args: argparse.Namespace) -> int:
    """Simulate; print one line per subject and a summary."""
    from pipeline.synthetic.write_captures import simulate_captures
    from pipeline.synthetic.capture import CaptureEffects, SimulationSettings

    if args.subjects < 1 or args.external < 0 or args.jobs < 1:
        raise InputError("--subjects must be >= 1, --external >= 0 and --jobs >= 1")
    effects = CaptureEffects(**{name: not getattr(args, f"no_{name}") for name in _EFFECTS})
    settings = dataclasses.replace(SimulationSettings(), resolution=args.resolution,
                                   extra_resolution=args.extra_resolution)
    total = args.subjects + args.external
    start = time.perf_counter()
    count = [0]

    def progress(name: str) -> None:
        count[0] += 1
        print(f"[{count[0]}/{total}] {name} ({time.perf_counter() - start:.0f} s)",
              file=sys.stderr, flush=True)

    simulate_captures(args.output, args.subjects, seed=args.seed, settings=settings,
                      effects=effects, camera=args.camera, illuminant=args.illuminant,
                      n_external=args.external, jobs=args.jobs, progress=progress)
    off = [n for n in _EFFECTS if not getattr(effects, n)]
    print(f"wrote {args.output}: {args.subjects} subjects, {args.external} external scans "
          f"in {time.perf_counter() - start:.0f} s"
          + (f" (effects off: {', '.join(off)})" if off else ""))
    return 0
