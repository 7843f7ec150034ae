"""Scene (render) parameters, as immutable NamedTuple pytrees, and parameter blocks.

Conventions are scalismo-faces' (see ``reference-sampler.md`` §1): pose maps the
model frame to the world (``p_w = t + Rz(roll) Ry(yaw) Rx(pitch) (s p)``), the
camera looks down -z, the principal point is in NDC units, SH coefficients are
in scalismo's internal order (1, y, z, x, xy, yz, 3z^2-1, xz, x^2-y^2) and form
a radiance environment map (Lambert factors are applied when shading).

This module imports nothing from the project.
"""

from __future__ import annotations

import enum
from typing import NamedTuple

import numpy as np

__all__ = [
    "Block", "Pose", "View", "Camera", "SHLight", "DirectionalLight", "ColorTransform",
    "ImageSize", "LUMA", "MoMoCoefficients", "RenderParameter", "SH_N0", "default_square",
    "fit_to_image_size",
]

SH_N0 = 0.5 * np.sqrt(1.0 / np.pi)
SH_N1 = 0.5 * np.sqrt(3.0 / np.pi)


class Block(enum.Flag):
    """Parameter blocks; a proposal declares which ones it changes."""

    NONE = 0
    SHAPE = enum.auto()
    EXPRESSION = enum.auto()
    POSE = enum.auto()
    CAMERA = enum.auto()
    ALBEDO = enum.auto()
    LIGHT = enum.auto()
    COLOR_TRANSFORM = enum.auto()
    SPECULAR_EXPONENT = enum.auto()
    #: The directional light's direction (sampled as azimuth and elevation): its cast shadows
    #: depend on it, not on its strength.
    DIRECTIONAL_ANGLES = enum.auto()
    #: The directional light's RGB strengths (ambient, diffuse, specular) and shininess.
    DIRECTIONAL_STRENGTH = enum.auto()

    GEOMETRY = SHAPE | EXPRESSION
    RAYS = POSE | CAMERA
    DIRECTIONAL = DIRECTIONAL_ANGLES | DIRECTIONAL_STRENGTH
    ALL = (SHAPE | EXPRESSION | POSE | CAMERA | ALBEDO | LIGHT | COLOR_TRANSFORM | SPECULAR_EXPONENT
           | DIRECTIONAL)


def _vec(x, n: int) -> tuple[float, ...]:
    t = tuple(float(v) for v in np.asarray(x, np.float64).reshape(-1))
    if len(t) != n:
        raise ValueError(f"expected {n} values, got {len(t)}")
    return t


class Pose(NamedTuple):
    """Model-to-world transform: scaling, translation (mm) and Euler angles (rad)."""

    scaling: float = 1.0
    translation: tuple[float, float, float] = (0.0, 0.0, -1000.0)
    roll: float = 0.0
    yaw: float = 0.0
    pitch: float = 0.0


class View(NamedTuple):
    """The camera's pose in the world (identity in all fits)."""

    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    roll: float = 0.0
    yaw: float = 0.0
    pitch: float = 0.0


class Camera(NamedTuple):
    """Pinhole camera. ``principal_point`` is in NDC units (not pixels)."""

    focal_length: float = 7.5
    sensor_size: tuple[float, float] = (2.0, 2.0)
    near: float = 10.0
    far: float = 1e6
    principal_point: tuple[float, float] = (0.0, 0.0)
    orthographic: bool = False


class SHLight(NamedTuple):
    """Spherical-harmonics environment map, (K, 3) in scalismo's internal order."""

    coefficients: np.ndarray

    @classmethod
    def empty(cls) -> SHLight:
        """Return the empty light (K = 0 coefficients: no SH illumination)."""
        return cls(np.zeros((0, 3)))

    @classmethod
    def ambient_white(cls) -> SHLight:
        """L0 = 1/(pi N0): with the Lambert factor pi the shading equals the albedo."""
        c = np.zeros((9, 3))
        c[0] = 1.0 / (np.pi * SH_N0)
        return cls(c)

    @classmethod
    def frontal(cls, ambient: float = 0.8, diffuse: float = 0.2) -> SHLight:
        """Return scalismo's ``SH.frontal``: shading ``ambient + diffuse * n_z`` (bands 0-1).

        L0 = ambient / (pi N0) and L_z = diffuse / (2 pi / 3 N1), so that with the
        Lambert factors the shading of a normal n is exactly ``ambient + diffuse n_z``
        (L0 = 0.9027, L2 = 0.19544 for the defaults, as in AlbedoMM's lminit).
        """
        c = np.zeros((9, 3))
        c[0] = ambient / (np.pi * SH_N0)
        c[2] = diffuse / (2.0 * np.pi / 3.0 * SH_N1)
        return cls(c)

    @property
    def bands(self) -> int:
        """Number of SH bands, sqrt(K)."""
        return int(np.sqrt(self.coefficients.shape[0]))


class DirectionalLight(NamedTuple):
    """Directional light (Lambert + Blinn-Phong), towards ``direction`` (world frame).

    A fit samples it as an azimuth and an elevation (:meth:`angles`,
    :meth:`from_angles`): ``direction = (sin az cos el, sin el, cos az cos el)``,
    so (0, 0) is the camera's direction (+z) and a positive azimuth lights the
    image's right side (+x), a positive elevation comes from above (+y).
    """

    ambient: tuple[float, float, float] = (0.0, 0.0, 0.0)
    diffuse: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    specular: tuple[float, float, float] = (0.0, 0.0, 0.0)
    shininess: float = 10.0

    @property
    def enabled(self) -> bool:
        """True when the light contributes anything."""
        return any(v != 0 for v in (*self.ambient, *self.diffuse, *self.specular))

    def angles(self) -> tuple[float, float]:
        """Return ``(azimuth, elevation)`` (rad) of :attr:`direction` (see the class notes)."""
        d = np.asarray(self.direction, np.float64)
        d = d / np.linalg.norm(d)
        return float(np.arctan2(d[0], d[2])), float(np.arcsin(np.clip(d[1], -1.0, 1.0)))

    @classmethod
    def from_angles(cls, azimuth: float, elevation: float, diffuse, *,
                    specular=None, shininess: float = 10.0) -> DirectionalLight:
        """Return a light from ``(azimuth, elevation)`` (rad) with RGB ``diffuse`` (no ambient).

        ``specular`` defaults to ``diffuse`` (the same light makes both terms).
        """
        ca = float(np.cos(elevation))
        direction = (float(np.sin(azimuth)) * ca, float(np.sin(elevation)),
                     float(np.cos(azimuth)) * ca)
        diffuse = _vec(diffuse, 3)
        return cls((0.0, 0.0, 0.0), diffuse, direction,
                   diffuse if specular is None else _vec(specular, 3), float(shininess))


#: Weights of the luminance ``Y(c)`` that the colour transform's contrast mixes in.
LUMA = (0.3, 0.59, 0.11)


class ColorTransform(NamedTuple):
    """``c' = gain * (contrast c + (1 - contrast) Y(c)) + offset``, Y = .3r + .59g + .11b."""

    gain: tuple[float, float, float] = (1.0, 1.0, 1.0)
    contrast: float = 1.0
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def is_identity(self) -> bool:
        """True when the transform leaves every colour unchanged."""
        return self.gain == (1.0, 1.0, 1.0) and self.contrast == 1.0 and self.offset == (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """Return M (3, 3) float64 with ``c' = M c + offset`` (row-vector colours: ``c @ M.T``)."""
        kappa = float(self.contrast)
        return np.asarray(self.gain, np.float64)[:, None] * (
            kappa * np.eye(3) + (1.0 - kappa) * np.outer(np.ones(3), np.asarray(LUMA)))


class ImageSize(NamedTuple):
    """Image size in pixels."""

    width: int
    height: int


class MoMoCoefficients(NamedTuple):
    """Model coefficients; ``albedo`` (the shared diffuse/specular coefficients) is ``color`` in ``.rps``."""

    shape: np.ndarray
    albedo: np.ndarray
    expression: np.ndarray
    model_uri: str = ""

    @classmethod
    def zeros(cls, shape: int = 0, albedo: int = 0, expression: int = 0, model_uri: str = ""):
        """Return zero coefficient vectors of the given lengths (the model mean)."""
        return cls(np.zeros(shape), np.zeros(albedo), np.zeros(expression), model_uri)


class RenderParameter(NamedTuple):
    """Everything a ``.rps`` file holds, plus the AlbedoMM specular exponent.

    ``specular_exponent`` is written to ``.rps`` as the extra top-level key
    ``"specularExponent"`` (scalismo readers ignore unknown keys).
    """

    pose: Pose
    view: View
    camera: Camera
    environment_map: SHLight
    directional_light: DirectionalLight
    momo: MoMoCoefficients
    image_size: ImageSize
    color_transform: ColorTransform
    specular_exponent: float = 20.0


def default_square() -> RenderParameter:
    """Return scalismo's ``RenderParameter.defaultSquare``: 512 x 512, face 1 m away, frontal SH."""
    return RenderParameter(
        pose=Pose(),
        view=View(),
        camera=Camera(),
        environment_map=SHLight.frontal(),
        directional_light=DirectionalLight(),
        momo=MoMoCoefficients.zeros(),
        image_size=ImageSize(512, 512),
        color_transform=ColorTransform(),
    )


def fit_to_image_size(params: RenderParameter, width: int, height: int) -> RenderParameter:
    """Resize the image keeping the focal length; the sensor is rescaled.

    The shorter image side keeps the sensor extent of the square default, so the
    focal length in pixels is ``f * min(W, H) / min(s_x, s_y)`` (937.5 px at 250²
    for the default camera).
    """
    cam = params.camera
    s = min(cam.sensor_size)
    m = min(width, height)
    sensor = (s * width / m, s * height / m)
    return params._replace(
        camera=cam._replace(sensor_size=sensor), image_size=ImageSize(int(width), int(height))
    )
