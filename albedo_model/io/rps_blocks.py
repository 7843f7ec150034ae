"""Readers and writers of the ``.rps`` parameter blocks shared by several versions.

Each reader takes the parsed JSON object of one block and the dotted path of
that block (for error messages) and returns the matching
:mod:`albedo_model.params` record; they raise
:class:`albedo_model.io.json_fields.FieldError`. The writers return the V4
JSON object of a block, with every number as a Python float (``json`` writes
``repr(float)``, which reads back bit-exactly).

This module imports only :mod:`albedo_model.params` and
:mod:`albedo_model.io.json_fields`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from albedo_model.io.json_fields import (
    FieldError,
    get_bool,
    get_int,
    get_number,
    get_number_list,
    get_rows,
    get_string,
    get_vector,
)
from albedo_model.params import (
    Camera,
    ColorTransform,
    DirectionalLight,
    ImageSize,
    MoMoCoefficients,
    Pose,
    SHLight,
    View,
)

__all__ = [
    "check_type", "read_pose", "read_view", "read_camera", "read_color_transform",
    "read_image_size", "read_sh_light", "read_directional_light", "read_momo",
    "pose_json", "view_json", "camera_json", "sh_light_json", "directional_light_json",
    "momo_json", "image_size_json", "color_transform_json",
]

JSON = dict[str, Any]


def check_type(obj: JSON, where: str, allowed: tuple[str, ...], *, required: bool) -> str | None:
    """Validate the ``"@type"`` tag of a block; return it (None when absent and optional)."""
    if "@type" not in obj:
        if required:
            raise FieldError(f"missing field {where}.@type (one of {', '.join(allowed)})")
        return None
    tag = obj["@type"]
    if tag not in allowed:
        raise FieldError(f"{where}.@type is {tag!r}, expected one of {', '.join(allowed)}")
    return tag


def read_pose(obj: JSON, where: str = "pose") -> Pose:
    """``{scaling, translation, roll, yaw, pitch}`` (same in every version)."""
    return Pose(
        scaling=get_number(obj, "scaling", where),
        translation=get_vector(obj, "translation", 3, where),
        roll=get_number(obj, "roll", where),
        yaw=get_number(obj, "yaw", where),
        pitch=get_number(obj, "pitch", where),
    )


def read_view(obj: JSON, where: str = "view") -> View:
    """Read ``{translation, pitch, yaw, roll}`` (V3, V4; V1/V2 embed it in the camera)."""
    return View(
        translation=get_vector(obj, "translation", 3, where),
        roll=get_number(obj, "roll", where),
        yaw=get_number(obj, "yaw", where),
        pitch=get_number(obj, "pitch", where),
    )


def read_camera(obj: JSON, where: str = "camera") -> Camera:
    """V3/V4 camera: principal point already in NDC, plain sensor size."""
    return Camera(
        focal_length=get_number(obj, "focalLength", where),
        sensor_size=get_vector(obj, "sensorSize", 2, where),
        near=get_number(obj, "near", where),
        far=get_number(obj, "far", where),
        principal_point=get_vector(obj, "principalPoint", 2, where),
        orthographic=get_bool(obj, "orthographic", where),
    )


def read_color_transform(obj: JSON, where: str, contrast_key: str = "colorContrast"
                         ) -> ColorTransform:
    """``{gain, <contrast_key>, offset}``; V1 calls the contrast ``gamma``."""
    return ColorTransform(
        gain=get_vector(obj, "gain", 3, where),
        contrast=get_number(obj, contrast_key, where),
        offset=get_vector(obj, "offset", 3, where),
    )


def read_image_size(obj: JSON, where: str) -> ImageSize:
    """``{height, width}`` (V2 ``image``, V3/V4 ``imageSize``)."""
    size = ImageSize(width=get_int(obj, "width", where), height=get_int(obj, "height", where))
    if size.width <= 0 or size.height <= 0:
        raise FieldError(f"{where} must be positive, got {size.width} x {size.height}")
    return size


def read_sh_light(obj: JSON, where: str) -> SHLight:
    """``{coefficients: [[r, g, b], ...]}`` in the internal order (V2 and later)."""
    return SHLight(get_rows(obj, "coefficients", 3, where))


def read_directional_light(obj: JSON, where: str, shininess: float | None = None
                           ) -> DirectionalLight:
    """``{ambient, diffuse, direction, specular[, shininess]}``.

    ``shininess`` given: V1, which stores it with the model coefficients;
    otherwise the block must hold it.
    """
    return DirectionalLight(
        ambient=get_vector(obj, "ambient", 3, where),
        diffuse=get_vector(obj, "diffuse", 3, where),
        direction=get_vector(obj, "direction", 3, where),
        specular=get_vector(obj, "specular", 3, where),
        shininess=get_number(obj, "shininess", where) if shininess is None else shininess,
    )


def read_momo(obj: JSON, where: str, *, expression: bool) -> MoMoCoefficients:
    """``{shape, color[, expression], modelURI}`` (V2/V3 renderObject, V4 momo); ``color`` is the albedo."""
    return MoMoCoefficients(
        shape=get_number_list(obj, "shape", where),
        albedo=get_number_list(obj, "color", where),
        expression=get_number_list(obj, "expression", where) if expression else np.zeros(0),
        model_uri=get_string(obj, "modelURI", where),
    )


# -- V4 writers ----------------------------------------------------------------

def _floats(values: Any, n: int | None = None) -> list[float]:
    out = [float(v) for v in np.asarray(values, np.float64).reshape(-1)]
    if n is not None and len(out) != n:
        raise ValueError(f"expected {n} values, got {len(out)}")
    return out


def pose_json(pose: Pose) -> JSON:
    """Return the V4 ``pose`` object."""
    return {
        "scaling": float(pose.scaling), "translation": _floats(pose.translation, 3),
        "roll": float(pose.roll), "yaw": float(pose.yaw), "pitch": float(pose.pitch),
    }


def view_json(view: View) -> JSON:
    """Return the V4 ``view`` object."""
    return {
        "translation": _floats(view.translation, 3), "pitch": float(view.pitch),
        "yaw": float(view.yaw), "roll": float(view.roll),
    }


def camera_json(cam: Camera) -> JSON:
    """Return the V4 ``camera`` object (principal point in NDC)."""
    return {
        "focalLength": float(cam.focal_length), "sensorSize": _floats(cam.sensor_size, 2),
        "near": float(cam.near), "far": float(cam.far),
        "principalPoint": _floats(cam.principal_point, 2), "orthographic": bool(cam.orthographic),
    }


def sh_light_json(light: SHLight) -> JSON:
    """Return the V4 ``environmentMap`` object, (K, 3) coefficients in the internal order."""
    coeffs = np.asarray(light.coefficients, np.float64)
    if coeffs.size == 0:
        coeffs = coeffs.reshape(0, 3)
    if coeffs.ndim != 2 or coeffs.shape[1] != 3:
        raise ValueError(f"SH coefficients must have shape (K, 3), got {coeffs.shape}")
    return {"coefficients": [_floats(row) for row in coeffs], "@type": "SphericalHarmonicsLight"}


def directional_light_json(light: DirectionalLight) -> JSON:
    """Return the V4 ``directionalLight`` object."""
    return {
        "ambient": _floats(light.ambient, 3), "diffuse": _floats(light.diffuse, 3),
        "specular": _floats(light.specular, 3), "direction": _floats(light.direction, 3),
        "shininess": float(light.shininess), "@type": "DirectionalLight",
    }


def momo_json(momo: MoMoCoefficients) -> JSON:
    """Return the V4 ``momo`` object."""
    return {
        "shape": _floats(momo.shape), "color": _floats(momo.albedo),
        "expression": _floats(momo.expression), "modelURI": str(momo.model_uri),
    }


def image_size_json(size: ImageSize) -> JSON:
    """Return the V4 ``imageSize`` object."""
    return {"height": int(size.height), "width": int(size.width)}


def color_transform_json(ct: ColorTransform) -> JSON:
    """Return the V4 ``colorTransform`` object."""
    return {"gain": _floats(ct.gain, 3), "colorContrast": float(ct.contrast),
            "offset": _floats(ct.offset, 3)}
