"""``mcmcfit render MODEL PARAMS.rps -o out.png``: render the instance an .rps describes.

A model whose colour is a gamma-encoded sRGB texture (BFM 2017;
:func:`albedo_model.io.colour_space.model_colour_space`) renders encoded values
already: they are written as they are (``--linear`` decodes them), never
encoded a second time.

This module imports :mod:`albedo_model.errors`; :mod:`albedo_model` (``io``, ``params``,
``render.renderer``) and :mod:`mcmcfit.jobs.model_spec` are imported when it runs.
"""

from __future__ import annotations

import argparse
import re

from albedo_model.errors import InputError

__all__ = ["register", "run"]


def _size(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
        raise argparse.ArgumentTypeError(f"expected WxH with positive integers, got {text!r}")
    return int(m.group(1)), int(m.group(2))


def register(subparsers) -> None:
    """Add the ``render`` command."""
    p = subparsers.add_parser(
        "render", help="render the model instance described by a .rps file",
        description="Render the model instance of a .rps file (shape/colour/expression "
        "coefficients from its momo block; missing ones are zero). By default an RGBA PNG, "
        "gamma-encoded (pure power 1/2.2) 8-bit, transparent background; a model whose "
        "colour is an sRGB texture (BFM 2017) is written as rendered, not encoded twice. "
        "A directional light (scalismo's directionalLight) casts its shadows.",
    )
    p.add_argument("model", help="model file (.h5) or 'default'")
    p.add_argument("params", help="render parameters (.rps, any version)")
    p.add_argument("-o", "--output", required=True, help="output PNG")
    p.add_argument("--linear", action="store_true", help="write linear values as 16-bit PNG")
    p.add_argument("--specular-exponent", type=float, metavar="E",
                   help="AlbedoMM specular exponent (default: the .rps value, else 20)")
    p.add_argument("--size", type=_size, metavar="WxH",
                   help="image size (same camera; the principal point stays in NDC)")
    p.add_argument("--no-specular", action="store_true", help="diffuse only")
    p.add_argument("--no-shadows", action="store_true",
                   help="do not cast the directional light's shadows (cast by default when the "
                   ".rps has a directional light, as the fit renders it)")
    p.add_argument("--soft-shadows", type=int, default=1, metavar="K",
                   help="shadow rays per pixel over a light of 3 degrees radius (soft edges; "
                   "default 1: hard shadows)")
    p.add_argument("--model-colour", choices=("linear", "srgb"),
                   help="the model's colour space (default: read from the model file, else by "
                   "its layout)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Render the instance of ``args.params`` and write the PNG; return the exit code."""
    from albedo_model.io.colour_space import decode_texture, model_colour_space
    from albedo_model.io.image_io import write_png
    from albedo_model.io.rps import read_rps
    from albedo_model.params import ImageSize
    from albedo_model.render.renderer import Renderer
    from mcmcfit.jobs.model_spec import load_model_spec

    params = read_rps(args.params)
    model = load_model_spec(args.model)
    if args.size is not None:
        params = params._replace(image_size=ImageSize(*args.size))
    if args.specular_exponent is not None:
        if not args.specular_exponent > 0:
            raise InputError(f"--specular-exponent must be positive, got {args.specular_exponent}")
        params = params._replace(specular_exponent=float(args.specular_exponent))
    srgb = model_colour_space(model, getattr(args, "model_colour", None)).is_srgb
    if args.soft_shadows < 1:
        raise InputError(f"--soft-shadows must be >= 1, got {args.soft_shadows}")
    # the fit's image model: the directional light's highlight scaled by the specular albedo
    out = Renderer(model, specular=not args.no_specular, gamma=not (args.linear or srgb),
                   shadows=not args.no_shadows, shadow_rays=args.soft_shadows,
                   directional_specular_map=True).render(params)
    image = decode_texture(out.image) if srgb and args.linear else out.image
    write_png(args.output, image, alpha=out.mask, bits=16 if args.linear else 8)
    lit = params.directional_light.enabled
    shadows = "" if not lit else (", no cast shadows" if args.no_shadows else ", cast shadows")
    print(f"wrote {args.output} ({params.image_size.width}x{params.image_size.height}, "
          f"{int(out.mask.sum())} face pixels{shadows})")
    return 0
