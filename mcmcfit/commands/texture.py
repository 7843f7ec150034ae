"""``mcmcfit texture FIT [--size 1024]``: a fit's albedo and uncertainty as textures and a mesh.

This module imports nothing heavy when registering; :mod:`mcmcfit.jobs.texture_job`
is imported when it runs.
"""

from __future__ import annotations

import argparse

__all__ = ["register", "run"]


def register(subparsers) -> None:
    """Add the ``texture`` command."""
    p = subparsers.add_parser(
        "texture", help="bake a fit's posterior albedo and std into textures; OBJ and glTF mesh",
        description="Bake the per-vertex posterior mean and std of the diffuse and specular "
        "albedo of a fit (its posterior.npz) into square PNG textures through the model's UV "
        "atlas (16-bit linear and 8-bit sRGB), and write the posterior-mean mesh as OBJ+MTL "
        "and binary glTF with the diffuse texture on. Models without texture coordinates get "
        "an atlas computed once with xatlas (cached).",
    )
    p.add_argument("fit", help="a fit's result folder")
    p.add_argument("--size", type=int, default=1024, metavar="N",
                   help="texels a side (default 1024)")
    p.add_argument("-o", "--output", metavar="DIR", help="texture folder (default FIT/texture)")
    p.add_argument("--model", help="model file or built-in name (default: the fit's)")
    p.add_argument("--force", action="store_true", help="replace an existing texture folder")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run ``mcmcfit texture``; return the exit code."""
    from pathlib import Path

    from mcmcfit.jobs.texture_job import write_fit_textures

    record = write_fit_textures(args.fit, args.output, size=args.size, model=args.model,
                                force=args.force)
    out = Path(args.output) if args.output else Path(args.fit) / "texture"
    print(f"wrote {len(record['maps'])} maps at {record['size']}x{record['size']} and "
          f"{', '.join(record['mesh'])} to {out} in {record['seconds']:.1f} s (UV atlas: "
          f"{record['uv_atlas']}; round trip max error "
          f"{record['round_trip_max_abs_error'] * 255:.3f}/255)")
    return 0
