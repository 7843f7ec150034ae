"""``mcmcfit model sample MODEL --n 50 -o grid.png``: random faces, as in the paper's appendix.

Albedo coefficients are drawn from N(0, I); the shape stays at the mean. Each
face is rendered at a random yaw in [-30, 30] degrees with a white frontal
light (Lambert diffuse + Blinn-Phong with shininess 20, scaled by the sampled
specular albedo when the model has one), then gamma-encoded with the pure power
1/2.2, and the renders are tiled into one image. A model whose colour is a
gamma-encoded sRGB texture (BFM 2017;
:func:`albedo_model.io.colour_space.model_colour_space`) renders encoded values
already: they are shown as rendered, not encoded twice.

This module imports :mod:`albedo_model.errors`; :mod:`albedo_model` (``camera``,
``io.colour_space``, ``io.image_io``, ``params``, ``render.renderer``) and
:mod:`mcmcfit.jobs.model_spec` are imported when it runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from albedo_model.errors import InputError

__all__ = ["add_arguments", "run", "sample_faces"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``sample`` options to ``parser``."""
    parser.add_argument("model", metavar="MODEL", help="model file, or 'default'")
    parser.add_argument("--n", type=int, default=50, help="number of faces (default: 50)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    parser.add_argument("--size", type=int, default=200, help="pixels per face (default: 200)")
    parser.add_argument("--columns", type=int, default=10, help="faces per row (default: 10)")
    parser.add_argument("--max-yaw", type=float, default=30.0, help="degrees (default: 30)")
    parser.add_argument("-o", "--output", type=Path, required=True, help="grid image (.png)")
    parser.add_argument("--model-colour", choices=("linear", "srgb"),
                        help="the model's colour space (default: read from the model file, "
                        "else by its layout)")


def sample_faces(model, n: int, rng: np.random.Generator, *, size: int = 200,
                 max_yaw_deg: float = 30.0, model_colour: str | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Render ``n`` random albedo samples of ``model``.

    Parameters
    ----------
    model : MorphableModel
    n : int
    rng : numpy.random.Generator
    size : int
        Pixels per face.
    max_yaw_deg : float
    model_colour : {"linear", "srgb"}, optional
        The model's colour space (default: the model's,
        :func:`albedo_model.io.colour_space.model_colour_space`); an sRGB
        texture is not encoded again.

    Returns
    -------
    images : (n, size, size, 3) float32, gamma-encoded (as rendered for an sRGB-texture model)
    masks : (n, size, size) bool
    yaws : (n,) float64, radians
    """
    from albedo_model.io.colour_space import model_colour_space
    from albedo_model.params import (
        Block, DirectionalLight, ImageSize, MoMoCoefficients, Pose, SHLight, default_square,
    )
    from albedo_model.render.renderer import Renderer

    lo, hi = model.vertices.min(0), model.vertices.max(0)
    centre = (lo + hi) / 2
    extent = float(np.max(hi - lo))
    p = default_square()
    # f = 7.5 on a 2-unit sensor: half the image spans distance / 7.5
    distance = 7.5 * 0.62 * extent
    light = DirectionalLight(ambient=(0.0,) * 3, diffuse=(1.0,) * 3, direction=(0.0, 0.0, 1.0),
                             specular=(1.0,) * 3, shininess=20.0)
    p = p._replace(image_size=ImageSize(size, size), environment_map=SHLight.empty(),
                   directional_light=light)
    srgb = model_colour_space(model, model_colour).is_srgb
    renderer = Renderer(model, gamma=not srgb, directional_specular_map=True)
    yaws = rng.uniform(-1, 1, n) * np.deg2rad(max_yaw_deg)
    coeffs = rng.standard_normal((n, model.diffuse.rank))
    images = np.zeros((n, size, size, 3), np.float32)
    masks = np.zeros((n, size, size), bool)
    from albedo_model.camera import euler_rotation

    state = None
    for i in range(n):
        r = euler_rotation(0.0, yaws[i], 0.0)
        t = np.array([0.0, 0.0, -distance]) - r @ centre
        params = p._replace(pose=Pose(1.0, tuple(t), 0.0, float(yaws[i]), 0.0),
                            momo=MoMoCoefficients(np.zeros(0), coeffs[i], np.zeros(0)))
        if state is None:
            state = renderer.init_state(params)
        else:
            state = renderer.update(state, params, Block.POSE | Block.ALBEDO)
        out = renderer.image(state)
        images[i], masks[i] = out.image, out.mask
    return images, masks, yaws


def run(args: argparse.Namespace) -> int:
    """Render the grid and write it; return the exit code."""
    from albedo_model.io.image_io import write_png
    from mcmcfit.jobs.model_spec import load_model_spec

    if args.n < 1 or args.size < 16 or args.columns < 1:
        raise InputError("--n and --columns must be positive and --size at least 16")
    model = load_model_spec(args.model)
    images, masks, _ = sample_faces(model, args.n, np.random.default_rng(args.seed),
                                    size=args.size, max_yaw_deg=args.max_yaw,
                                    model_colour=getattr(args, "model_colour", None))
    cols = min(args.columns, args.n)
    rows = -(-args.n // cols)
    s = args.size
    grid = np.ones((rows * s, cols * s, 3), np.float32)
    for i, (img, m) in enumerate(zip(images, masks)):
        r, c = divmod(i, cols)
        grid[r * s:(r + 1) * s, c * s:(c + 1) * s] = np.where(m[..., None], img, 1.0)
    write_png(args.output, grid)
    print(f"wrote {args.output} ({args.n} faces, seed {args.seed})")
    return 0
