"""``mcmcfit model specgen``: leave-one-out generalisation of the specular model variants.

Builds the synthetic population (template head + subjects), computes the
leave-one-out specular error of the independent, concatenated and transferred
models (the paper's figure "specgen") and plots it. The ``model`` command
(:func:`mcmcfit.commands.model.register_specgen`) wires this module in with
:func:`add_arguments` and :func:`run`.

This module imports :mod:`albedo_model.errors` and :mod:`albedo_model.io.atomic`;
:mod:`pipeline.modelling.generalisation`, :mod:`pipeline.synthetic.subjects` and
:mod:`pipeline.synthetic.head.template_head` are imported when it runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.atomic import atomic_path

__all__ = ["add_arguments", "run"]

_REPORT_COMPONENTS = (0, 1, 2, 5, 10, 20, 40)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``specgen`` options to ``parser``."""
    parser.add_argument("--subjects", type=int, default=50, metavar="N",
                        help="number of synthetic subjects (default: 50)")
    parser.add_argument("--seed", type=int, default=0, metavar="S",
                        help="population seed (default: 0)")
    parser.add_argument("--max-components", type=int, default=None, metavar="K",
                        help="largest number of modes evaluated (default: all)")
    parser.add_argument("--no-augment", action="store_true",
                        help="build the models without symmetry augmentation")
    parser.add_argument("--json", type=Path, default=None, metavar="PATH",
                        help="also write the error curves as JSON")
    parser.add_argument("-o", "--output", type=Path, default=Path("specgen.png"),
                        help="output image (default: specgen.png)")


def _template():
    from pipeline.synthetic.head.template_head import build_template_head

    return build_template_head()


def run(args: argparse.Namespace) -> int:
    """Compute and plot the curves; print a short table; return the exit code."""
    from pipeline.modelling.generalisation import plot_specular_generalisation, specular_generalisation
    from pipeline.synthetic.subjects import make_subjects

    if args.subjects < 3:
        raise InputError(f"--subjects must be at least 3, got {args.subjects}")
    head = _template()
    subjects = make_subjects(head, args.subjects, args.seed)
    diffuse = np.stack([s.diffuse for s in subjects])
    specular = np.stack([s.specular for s in subjects])
    result = specular_generalisation(
        diffuse, specular, None if args.no_augment else head.symmetry,
        max_components=args.max_components,
    )
    plot_specular_generalisation(result, args.output)
    if args.json is not None:
        payload = {
            "n_subjects": result["n_subjects"], "n_vertices": result["n_vertices"],
            "augmented": result["augmented"], "seed": args.seed,
            "components": result["components"].tolist(),
            "fit_mean": {v: e.tolist() for v, e in result["fit_mean"].items()},
            "from_diffuse_mean": {v: e.tolist() for v, e in result["from_diffuse_mean"].items()},
        }
        with atomic_path(args.json) as tmp:
            tmp.write_text(json.dumps(payload, indent=1))
    ks = [k for k in _REPORT_COMPONENTS if k <= result["components"][-1]]
    out = sys.stdout
    out.write("RMS specular error (linear sRGB), leave-one-out mean; k = ")
    out.write(", ".join(map(str, ks)) + "\n")
    for key in ("fit_mean", "from_diffuse_mean"):
        for v, e in result[key].items():
            out.write(f"  {key[:-5]:<13} {v:<13} " + " ".join(f"{e[k]:.4f}" for k in ks) + "\n")
    out.write(f"wrote {args.output}\n")
    return 0
