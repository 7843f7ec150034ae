"""``mcmcfit model ACTION``: inspect and assemble model files.

Actions: ``info`` (sizes, parts and ranks, landmarks, colour space, SHA-256;
``--json`` for one JSON object), ``combine`` (BFM 2017 shape model +
AlbedoMM albedo part -> joint AlbedoMM file), ``sample``
(:mod:`mcmcfit.commands.model_sample`) and ``specgen``
(:mod:`mcmcfit.commands.model_specgen`). Further actions register by
appending a ``register_<action>(actions)`` function to :data:`ACTIONS`.

This module imports :mod:`albedo_model.io`, :mod:`mcmcfit.commands.subcommands` and
:mod:`mcmcfit.jobs.model_spec`; :mod:`mcmcfit.commands.model_sample` and
:mod:`mcmcfit.commands.model_specgen` are imported when their actions register.
"""

from __future__ import annotations

import argparse
import json
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import Any

from albedo_model.io.colour_space import ColourSpace, resolve_colour_space
from albedo_model.io.flame_npz import read_flame_albedo_npz
from albedo_model.io.model_files import (
    combine_model_files,
    file_sha256,
    load_model,
    model_file_kind,
)
from albedo_model.io.momo_h5 import read_albedo_part
from mcmcfit.commands.subcommands import add_action
from mcmcfit.jobs.model_spec import resolve_model

__all__ = ["register", "ACTIONS", "model_info"]

_FORMATS = {
    "momo": "scalismo MoMo HDF5",
    "albedomm": "AlbedoMM HDF5 (joint model)",
    "albedo-part": "AlbedoMM albedo part HDF5",
    "flame-npz": "AlbedoMM FLAME albedo npz (texture space)",
}


def model_info(spec: str) -> dict[str, Any]:
    """Summary of a model file as a JSON-ready dict.

    Keys: ``path``, ``sha256``, ``format``, ``vertices``, ``triangles``,
    ``parts`` (name -> rank), ``shared_albedo``, ``landmarks`` (names),
    ``landmarks_on_vertices``, ``colour_space`` (what the metadata says, or
    None), ``model_colour`` (the colour space a fit reads, ``value`` "linear" or
    "srgb", ``source`` and ``label``: :func:`albedo_model.io.colour_space.resolve_colour_space`),
    ``metadata``; a FLAME npz also has ``texture_shape`` (and
    ``vertices``/``triangles`` are None).
    """
    path = resolve_model(spec)
    kind = model_file_kind(path)
    info: dict[str, Any] = {
        "path": str(path), "sha256": file_sha256(path), "format": _FORMATS[kind],
    }
    if kind == "flame-npz":
        albedo = read_flame_albedo_npz(path)
        parts = {"diffuse": albedo.diffuse.rank}
        if albedo.specular is not None:
            parts["specular"] = albedo.specular.rank
        info.update(
            vertices=None, triangles=None, parts=parts, shared_albedo=True, landmarks=[],
            landmarks_on_vertices=0, colour_space="linear sRGB",
            texture_shape=list(albedo.texture_shape), metadata={},
            model_colour=_colour(resolve_colour_space({}, has_specular=True)),
        )
    elif kind == "albedo-part":
        part = read_albedo_part(path)
        verts = part.vertices.astype(float)
        # the rule of MorphableModel.landmark_vertices: within 1e-3 mm of a vertex
        on_vertices = sum(
            bool(((verts - p) ** 2).sum(1).min() <= 1e-6) for p in part.landmarks.values()
        )
        info.update(
            vertices=len(part.vertices), triangles=len(part.triangles),
            parts={"diffuse": part.diffuse.rank, "specular": part.specular.rank},
            shared_albedo=True, landmarks=list(part.landmarks), landmarks_on_vertices=on_vertices,
            colour_space=part.metadata.get("colour_space"), metadata=part.metadata,
            model_colour=_colour(resolve_colour_space(part.metadata, has_specular=True)),
        )
    else:
        model = load_model(path)
        info.update(
            vertices=model.n_vertices, triangles=model.n_triangles, parts=model.ranks,
            shared_albedo=model.shared_albedo, landmarks=list(model.landmarks),
            landmarks_on_vertices=len(model.landmark_vertices),
            colour_space=model.metadata.get("colour_space"), metadata=dict(model.metadata),
            model_colour=_colour(resolve_colour_space(
                model.metadata, has_specular=model.specular is not None)),
        )
    return info


def _colour(space: ColourSpace) -> dict[str, str]:
    return {"value": space.value, "source": space.source, "label": space.label}


def _colour_line(colour: dict[str, str]) -> str:
    return f"{colour['value']} ({colour['label']}; from {colour['source']})"


def _print_info(info: dict[str, Any]) -> None:
    rows = [
        ("path", info["path"]), ("sha256", info["sha256"]), ("format", info["format"]),
        ("vertices", info["vertices"]), ("triangles", info["triangles"]),
        ("parts", ", ".join(f"{k} {v}" for k, v in info["parts"].items())),
        ("shared albedo", "yes" if info["shared_albedo"] else "no"),
        ("colour space", _colour_line(info["model_colour"])),
        ("landmarks", f"{len(info['landmarks'])} ({info['landmarks_on_vertices']} on vertices)"),
    ]
    if "texture_shape" in info:
        rows.insert(3, ("texture", " x ".join(map(str, info["texture_shape"]))))
    for key, value in rows:
        print(f"{key + ':':15s}{value}")
    if info["landmarks"]:
        print(textwrap.fill(", ".join(info["landmarks"]), 100, initial_indent=" " * 15,
                            subsequent_indent=" " * 15, break_on_hyphens=False))
    if info["metadata"]:
        print("metadata:")
        for key, value in info["metadata"].items():
            print(f"  {key}: {value}")


def _run_info(args: argparse.Namespace) -> int:
    info = model_info(args.model)
    if args.json:
        print(json.dumps(info))
    else:
        _print_info(info)
    return 0


def _run_combine(args: argparse.Namespace) -> int:
    model = combine_model_files(args.shape, args.albedo, args.output)
    ranks = ", ".join(f"{k} {v}" for k, v in model.ranks.items())
    print(f"wrote {args.output}: {model.n_vertices} vertices, {model.n_triangles} triangles, "
          f"{ranks}")
    return 0


def register_info(actions: argparse._SubParsersAction) -> None:
    """Add ``model info``."""
    p = add_action(
        actions, "info", _run_info, help="describe a model file",
        description="Sizes, parts and ranks, landmarks, colour space and SHA-256 of a model file.",
    )
    p.add_argument("model", metavar="MODEL", help="model file, or 'default' for the built-in model")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def register_combine(actions: argparse._SubParsersAction) -> None:
    """Add ``model combine``."""
    p = add_action(
        actions, "combine", _run_combine,
        help="build the joint AlbedoMM model from BFM 2017 and an albedo part",
        description="Shape, expression and landmarks from --shape, diffuse and specular albedo "
                    "from --albedo; both must share one mesh topology.",
    )
    p.add_argument("--shape", required=True, type=Path, help="e.g. model2017-1_face12_nomouth.h5")
    p.add_argument("--albedo", required=True, type=Path,
                   help="e.g. albedoModel2020_face12_albedoPart.h5")
    p.add_argument("-o", "--output", required=True, type=Path, help="joint model to write (.h5)")


def register_sample(actions: argparse._SubParsersAction) -> None:
    """Add ``model sample``."""
    from mcmcfit.commands import model_sample

    add_action(
        actions, "sample", model_sample.run, arguments=model_sample.add_arguments,
        help="render random albedo samples of a model as a grid",
        description="Random faces (albedo ~ N(0, I), mean shape) at random yaw in +-30 degrees, "
                    "white frontal light, Blinn-Phong (shininess 20), gamma 2.2.",
    )


def register_specgen(actions: argparse._SubParsersAction) -> None:
    """Add ``model specgen``."""
    from mcmcfit.commands import model_specgen

    add_action(
        actions, "specgen", model_specgen.run, arguments=model_specgen.add_arguments,
        help="leave-one-out generalisation of the three specular model variants",
        description="Builds the synthetic population and plots the leave-one-out specular "
                    "error of the independent, concatenated and transferred models.",
    )


#: One registrar per ``model`` action, in help order.
ACTIONS: list[Callable[[argparse._SubParsersAction], None]] = [
    register_info, register_combine, register_sample, register_specgen,
]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``model`` command group and its actions."""
    parser = subparsers.add_parser("model", help="inspect and assemble model files")
    actions = parser.add_subparsers(dest="model_action", metavar="ACTION", required=True)
    for add in ACTIONS:
        add(actions)
