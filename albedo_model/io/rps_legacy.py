"""Readers of the historic ``.rps`` versions V1 (legacy), V2 and V3.

Facts (scalismo-faces ``io/renderparameters``, checked on the fixtures
``renderParametersV1..V3.rps``, which all describe the same scene):

* **V1** has no ``version`` key (or ``""``, ``"legacy"``, ``"1.0"``, ``"V1.0"``).

  - ``camera`` embeds the view (``translation``, ``pitch``, ``yaw``, ``roll``).
    Its ``principlePoint`` (sic) is in pixels; its ``sensorSize`` is stored
    multiplied by ``near``, so the sensor is ``sensorSize / near``. The
    ``skewFactor`` is ignored: scalismo's camera has no skew, and its writer
    always wrote 1.0.
  - ``image`` is ``[height, width]``, in that order.
  - ``color`` is ``{gain, gamma, offset}``, where ``gamma`` is the colour contrast.
  - ``morphableModel`` is ``{shapeCoefficients, colorCoefficients, modelURI,
    shininess}``; there are no expression coefficients.
  - ``sphericalHarmonicsLight`` is a bare list of at most 9 RGB rows in the legacy
    order [1, x, y, z, z², yz, xz, xy, x²−y²]: internal[i] = legacy[perm[i]],
    with perm = (0, 2, 3, 1, 7, 5, 4, 6, 8). Fewer than 9 rows use the prefix of
    perm (the 4 rows of the fixture map to internal rows 0, 2, 3, 1).
  - ``directionalLight`` has no shininess; it is read only when the SH light is
    empty, taking ``morphableModel.shininess``. With an SH light, the directional
    light is "off", exactly as scalismo reads it (the renderer uses SH when it is
    non-empty, so nothing is lost).
* **V2** is like V1, with these differences:

  - the camera key is spelled ``principalPoint`` (still in pixels);
  - ``sensorSize`` is plain, not multiplied by ``near``;
  - ``illumination`` carries ``@type`` SphericalHarmonicsLight (coefficients in
    the internal order) or DirectionalLight (with shininess); the other light
    is empty or off;
  - ``renderObject`` carries ``@type`` MoMoInstance or MoMoExpressInstance (the
    latter with ``expression``);
  - ``image`` is ``{height, width}``;
  - ``color`` is ``{gain, colorContrast, offset}``.
* **V3** has ``pose``, ``view``, a camera with an NDC principal point, V2's
  ``illumination`` and ``renderObject``, ``imageSize`` and ``colorTransform``.

Pixel principal points convert as pp_ndc = 2·pp_px / size (x with the width,
y with the height, no y flip).

This module imports only :mod:`albedo_model.params` and :mod:`albedo_model.io`
helpers (``json_fields``, ``rps_blocks``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from albedo_model.io.json_fields import (
    FieldError,
    get_bool,
    get_number,
    get_number_list,
    get_object,
    get_rows,
    get_string,
    get_vector,
)
from albedo_model.io.rps_blocks import (
    check_type,
    read_camera,
    read_color_transform,
    read_directional_light,
    read_image_size,
    read_momo,
    read_pose,
    read_sh_light,
    read_view,
)
from albedo_model.params import (
    Camera,
    DirectionalLight,
    ImageSize,
    MoMoCoefficients,
    RenderParameter,
    SHLight,
    View,
)

__all__ = ["LEGACY_SH_TO_INTERNAL", "read_v1", "read_v2", "read_v3", "sh_from_legacy_order"]

JSON = dict[str, Any]

#: internal SH row i = legacy (V1) row LEGACY_SH_TO_INTERNAL[i]
LEGACY_SH_TO_INTERNAL = (0, 2, 3, 1, 7, 5, 4, 6, 8)


def sh_from_legacy_order(legacy: np.ndarray) -> np.ndarray:
    """Reorder (K, 3) SH rows from the V1 order to the internal order, K <= 9.

    Parameters
    ----------
    legacy : (K, 3) float64
        Rows in the order [1, x, y, z, z², yz, xz, xy, x²−y²] (first K of them).

    Returns
    -------
    (K, 3) float64
        Rows in the internal order (1, y, z, x, xy, yz, 3z²−1, xz, x²−y²).
    """
    k = legacy.shape[0]
    if k > len(LEGACY_SH_TO_INTERNAL):
        raise ValueError(f"the V1 order defines at most 9 SH coefficients, got {k}")
    return legacy[list(LEGACY_SH_TO_INTERNAL[:k])].copy()


def _pixels_to_ndc(pp_px: tuple[float, ...], size: ImageSize) -> tuple[float, float]:
    return (2.0 * pp_px[0] / size.width, 2.0 * pp_px[1] / size.height)


def _camera_with_view(obj: JSON, size: ImageSize, *, pp_key: str, sensor_times_near: bool
                      ) -> tuple[Camera, View]:
    """V1/V2 camera block: pixel principal point, embedded view."""
    near = get_number(obj, "near", "camera")
    sensor = get_vector(obj, "sensorSize", 2, "camera")
    if sensor_times_near:
        if near == 0.0:
            raise FieldError("camera.near is 0: V1 sensor size (sensorSize / near) is undefined")
        sensor = (sensor[0] / near, sensor[1] / near)
    if "skewFactor" in obj:
        get_number(obj, "skewFactor", "camera")  # validated, not used (see module docstring)
    camera = Camera(
        focal_length=get_number(obj, "focalLength", "camera"),
        sensor_size=sensor,
        near=near,
        far=get_number(obj, "far", "camera"),
        principal_point=_pixels_to_ndc(get_vector(obj, pp_key, 2, "camera"), size),
        orthographic=get_bool(obj, "orthographic", "camera"),
    )
    return camera, read_view(obj, "camera")


def _v1_image_size(data: JSON) -> ImageSize:
    if "image" not in data:
        raise FieldError("missing field image")
    image = data["image"]
    if not isinstance(image, list) or len(image) != 2:
        raise FieldError("image must be a list [height, width]")
    return read_image_size({"height": image[0], "width": image[1]}, "image")


def read_v1(data: JSON) -> RenderParameter:
    """Parse a V1 (legacy) ``.rps`` JSON object; raises ``FieldError``."""
    size = _v1_image_size(data)

    momo_obj = get_object(data, "morphableModel")
    momo = MoMoCoefficients(
        shape=get_number_list(momo_obj, "shapeCoefficients", "morphableModel"),
        albedo=get_number_list(momo_obj, "colorCoefficients", "morphableModel"),
        expression=np.zeros(0),
        model_uri=get_string(momo_obj, "modelURI", "morphableModel"),
    )
    shininess = get_number(momo_obj, "shininess", "morphableModel")

    sh_rows = get_rows(data, "sphericalHarmonicsLight", 3)
    if sh_rows.shape[0] > 9:
        raise FieldError("sphericalHarmonicsLight: the V1 order defines at most 9 "
                         f"coefficients, got {sh_rows.shape[0]}")
    sh = SHLight(sh_from_legacy_order(sh_rows))
    if sh_rows.shape[0] > 0:
        directional = DirectionalLight()
    else:
        directional = read_directional_light(
            get_object(data, "directionalLight"), "directionalLight", shininess=shininess)

    camera, view = _camera_with_view(get_object(data, "camera"), size,
                                     pp_key="principlePoint", sensor_times_near=True)
    return RenderParameter(
        pose=read_pose(get_object(data, "pose")),
        view=view,
        camera=camera,
        environment_map=sh,
        directional_light=directional,
        momo=momo,
        image_size=size,
        color_transform=read_color_transform(get_object(data, "color"), "color", "gamma"),
    )


def _illumination(obj: JSON) -> tuple[SHLight, DirectionalLight]:
    tag = check_type(obj, "illumination", ("SphericalHarmonicsLight", "DirectionalLight"),
                     required=True)
    if tag == "SphericalHarmonicsLight":
        return read_sh_light(obj, "illumination"), DirectionalLight()
    return SHLight.empty(), read_directional_light(obj, "illumination")


def _render_object(obj: JSON) -> MoMoCoefficients:
    tag = check_type(obj, "renderObject", ("MoMoInstance", "MoMoExpressInstance"), required=True)
    return read_momo(obj, "renderObject", expression=tag == "MoMoExpressInstance")


def read_v2(data: JSON) -> RenderParameter:
    """Parse a V2 ``.rps`` JSON object; raises ``FieldError``."""
    size = read_image_size(get_object(data, "image"), "image")
    camera, view = _camera_with_view(get_object(data, "camera"), size,
                                     pp_key="principalPoint", sensor_times_near=False)
    sh, directional = _illumination(get_object(data, "illumination"))
    return RenderParameter(
        pose=read_pose(get_object(data, "pose")),
        view=view,
        camera=camera,
        environment_map=sh,
        directional_light=directional,
        momo=_render_object(get_object(data, "renderObject")),
        image_size=size,
        color_transform=read_color_transform(get_object(data, "color"), "color"),
    )


def read_v3(data: JSON) -> RenderParameter:
    """Parse a V3 ``.rps`` JSON object; raises ``FieldError``."""
    sh, directional = _illumination(get_object(data, "illumination"))
    return RenderParameter(
        pose=read_pose(get_object(data, "pose")),
        view=read_view(get_object(data, "view")),
        camera=read_camera(get_object(data, "camera")),
        environment_map=sh,
        directional_light=directional,
        momo=_render_object(get_object(data, "renderObject")),
        image_size=read_image_size(get_object(data, "imageSize"), "imageSize"),
        color_transform=read_color_transform(get_object(data, "colorTransform"),
                                             "colorTransform"),
    )
