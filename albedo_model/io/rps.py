"""``.rps`` render-parameter JSON: read versions V1-V4, write V4.

The reader dispatches on the top-level ``version`` string like scalismo-faces:
absent, ``""``, ``"legacy"``, ``"1.0"`` or ``"V1.0"`` mean V1; ``"V2.0"``,
``"V3.0"`` and ``"V4.0"`` their versions; anything else is an error. The
historic versions are described in :mod:`albedo_model.io.rps_legacy`.

V4 layout (as written here, key order as in scalismo's fixtures)::

    pose{scaling, translation, roll, yaw, pitch}
    view{translation, pitch, yaw, roll}
    camera{focalLength, sensorSize, near, far, principalPoint (NDC), orthographic}
    environmentMap{coefficients (K x 3, internal SH order), @type}
    directionalLight{ambient, diffuse, specular, direction, shininess, @type}
    momo{shape, color, expression, modelURI}
    imageSize{height, width}
    colorTransform{gain, colorContrast, offset}
    version "V4.0"
    specularExponent

``specularExponent`` (AlbedoMM's specular exponent, default 20) is this
project's addition; scalismo ignores unknown keys. It is read from any version
when present. The writer emits the ``@type`` tags of scalismo's older (spray)
V4 writer, as in AlbedoMM's files; its newer (upickle) writer omits them, as in
``renderParametersV4.rps``. The reader accepts both, but a tag that is present
must be right.

Every number is written with Python's shortest round-trip ``repr``, so
``read_rps(write_rps(p))`` reproduces ``p`` exactly.

This module imports only :mod:`albedo_model.params`, :mod:`albedo_model.errors`
and :mod:`albedo_model.io` helpers.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from albedo_model.errors import FormatError, InputError
from albedo_model.io.atomic import atomic_path
from albedo_model.io.json_fields import FieldError, get_number, get_object
from albedo_model.io.rps_blocks import (
    camera_json,
    check_type,
    color_transform_json,
    directional_light_json,
    image_size_json,
    momo_json,
    pose_json,
    read_camera,
    read_color_transform,
    read_directional_light,
    read_image_size,
    read_momo,
    read_pose,
    read_sh_light,
    read_view,
    sh_light_json,
    view_json,
)
from albedo_model.io.rps_legacy import read_v1, read_v2, read_v3
from albedo_model.io.text_files import read_text_file
from albedo_model.params import RenderParameter

__all__ = [
    "RPS_WRITE_VERSION", "rps_version", "parse_rps_dict", "format_rps_dict", "parse_rps_text",
    "format_rps_text", "read_rps", "write_rps",
]

JSON = dict[str, Any]

#: the version string the writer emits
RPS_WRITE_VERSION = "V4.0"

_V1_NAMES = ("", "legacy", "1.0", "V1.0")


def read_v4(data: JSON) -> RenderParameter:
    """Parse a V4 ``.rps`` JSON object; raises ``FieldError``."""
    env = get_object(data, "environmentMap")
    check_type(env, "environmentMap", ("SphericalHarmonicsLight",), required=False)
    light = get_object(data, "directionalLight")
    check_type(light, "directionalLight", ("DirectionalLight",), required=False)
    return RenderParameter(
        pose=read_pose(get_object(data, "pose")),
        view=read_view(get_object(data, "view")),
        camera=read_camera(get_object(data, "camera")),
        environment_map=read_sh_light(env, "environmentMap"),
        directional_light=read_directional_light(light, "directionalLight"),
        momo=read_momo(get_object(data, "momo"), "momo", expression=True),
        image_size=read_image_size(get_object(data, "imageSize"), "imageSize"),
        color_transform=read_color_transform(get_object(data, "colorTransform"),
                                             "colorTransform"),
    )


_READERS: dict[str, Callable[[JSON], RenderParameter]] = {
    "V1.0": read_v1, "V2.0": read_v2, "V3.0": read_v3, "V4.0": read_v4,
}


def rps_version(data: JSON) -> str:
    """Return the normalised version (``"V1.0"`` ... ``"V4.0"``) of a parsed ``.rps`` object.

    Raises
    ------
    ValueError
        Unknown version, or a ``version`` that is not a string.
    """
    if "version" not in data:
        return "V1.0"
    version = data["version"]
    if not isinstance(version, str):
        raise ValueError(f"version must be a string, got {version!r}")
    if version in _V1_NAMES:
        return "V1.0"
    if version in _READERS:
        return version
    raise ValueError(f"unknown .rps version {version!r} (known: V1.0, V2.0, V3.0, V4.0)")


def parse_rps_dict(data: Any, source: str | os.PathLike | None = None) -> RenderParameter:
    """Parse the JSON object of an ``.rps`` file of any version.

    Parameters
    ----------
    data : dict
        The parsed JSON document.
    source : path-like, optional
        Named in error messages.

    Returns
    -------
    RenderParameter
        Principal point in NDC, SH in the internal order, ``specular_exponent``
        from ``specularExponent`` when present (else 20).

    Raises
    ------
    FormatError
        Unknown version, missing field or wrongly typed value; the message names
        the field (``missing field camera.principalPoint``) and the version.
    """
    if not isinstance(data, dict):
        raise FormatError(source, "an .rps file must hold a JSON object")
    try:
        version = rps_version(data)
    except ValueError as exc:
        raise FormatError(source, str(exc)) from None
    try:
        params = _READERS[version](data)
        if "specularExponent" in data:
            params = params._replace(specular_exponent=get_number(data, "specularExponent"))
    except FieldError as exc:
        raise FormatError(source, f"{exc} (reading .rps {version})") from None
    return params


def format_rps_dict(params: RenderParameter) -> JSON:
    """Build the V4 JSON object of ``params`` (plain Python types, fixtures' key order).

    Raises
    ------
    InputError
        A parameter block has the wrong length or shape.
    """
    try:
        return {
            "pose": pose_json(params.pose),
            "view": view_json(params.view),
            "camera": camera_json(params.camera),
            "environmentMap": sh_light_json(params.environment_map),
            "directionalLight": directional_light_json(params.directional_light),
            "momo": momo_json(params.momo),
            "imageSize": image_size_json(params.image_size),
            "colorTransform": color_transform_json(params.color_transform),
            "version": RPS_WRITE_VERSION,
            "specularExponent": float(params.specular_exponent),
        }
    except (ValueError, TypeError) as exc:
        raise InputError(f"cannot write render parameters: {exc}") from None


def _reject_constant(name: str) -> float:
    raise ValueError(f"non-standard JSON number {name}")


def parse_rps_text(text: str, source: str | os.PathLike | None = None) -> RenderParameter:
    """Parse ``.rps`` JSON text (any version); raises ``FormatError``."""
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise FormatError(source, f"malformed JSON: {exc.msg} at line {exc.lineno}, "
                                  f"column {exc.colno}") from None
    except ValueError as exc:
        raise FormatError(source, f"malformed JSON: {exc}") from None
    return parse_rps_dict(data, source)


def _dumps(value: Any, level: int = 0) -> str:
    """JSON with one key per line and every list on one line, as in scalismo's fixtures."""
    if isinstance(value, dict):
        inner = "  " * (level + 1)
        items = [f"{inner}{json.dumps(k)}: {_dumps(v, level + 1)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + "\n" + "  " * level + "}"
    return json.dumps(value, allow_nan=False)


def format_rps_text(params: RenderParameter) -> str:
    """V4 JSON text of ``params`` (one key per line, lists on one line, final newline)."""
    data = format_rps_dict(params)
    try:
        return _dumps(data) + "\n"
    except ValueError:
        raise InputError("cannot write render parameters: a value is NaN or infinite") from None


def read_rps(path: str | os.PathLike) -> RenderParameter:
    """Read an ``.rps`` file of any version (V1-V4).

    Parameters
    ----------
    path : path-like
        The ``.rps`` JSON file.

    Returns
    -------
    RenderParameter

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    FormatError
        The file is not UTF-8 JSON, or not a valid ``.rps`` of a known version.
    """
    path = Path(path)
    text = read_text_file(path, "an .rps JSON file")
    return parse_rps_text(text, path)


def write_rps(path: str | os.PathLike, params: RenderParameter) -> None:
    """Write ``params`` as a V4 ``.rps`` file, atomically.

    Parameters
    ----------
    path : path-like
        Destination; its folder must exist. On failure nothing is written and an
        existing file is left untouched.
    params : RenderParameter

    Raises
    ------
    InputError
        ``params`` cannot be represented (wrong shapes, NaN or infinity).
    """
    text = format_rps_text(params)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
