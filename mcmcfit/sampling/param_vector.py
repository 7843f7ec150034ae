"""Flat float64 vectors of the sampled parameters, for chain records and summaries.

A :class:`ParamLayout` fixes, for one fit, which scalar sits in which column:

==========================  ==================================================
``pose.yaw/pitch/roll``     rad
``pose.tx/ty/tz``           mm (``pose.translation``)
``pose.scaling``            (never sampled; kept for round trips)
``camera.focal_length``     sensor units
``camera.pp_x/pp_y``        NDC
``light.<i>.<r|g|b>``       SH coefficient i (scalismo order), K x 3 columns
``color_transform.gain.<r|g|b>``,
``color_transform.contrast``,
``color_transform.offset.<r|g|b>``
``specular_exponent``
``shape.<i>``, ``albedo.<i>``, ``expression.<i>``   model coefficients
``directional.azimuth``,    the directional light (only when the fit has one):
``directional.elevation``,  rad and RGB strength
``directional.<r|g|b>``
==========================  ==================================================

Fields that are never sampled (view, image size, sensor, near/far,
orthographic flag, the directional light's shininess, model URI) come from a
template when a vector is turned back into parameters.

This module imports only :mod:`albedo_model.errors` and :mod:`albedo_model.params`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import ColorTransform, DirectionalLight, RenderParameter, SHLight

__all__ = ["ParamLayout"]

_POSE = ("pose.yaw", "pose.pitch", "pose.roll", "pose.tx", "pose.ty", "pose.tz", "pose.scaling")
_CAMERA = ("camera.focal_length", "camera.pp_x", "camera.pp_y")
_DIRECTIONAL = ("directional.azimuth", "directional.elevation", "directional.r",
                "directional.g", "directional.b")
_COLOR_TRANSFORM = ("color_transform.gain.r", "color_transform.gain.g", "color_transform.gain.b",
                    "color_transform.contrast", "color_transform.offset.r",
                    "color_transform.offset.g", "color_transform.offset.b")


@dataclass(frozen=True)
class ParamLayout:
    """Column layout of parameter vectors for given block sizes.

    Attributes
    ----------
    n_light : int
        SH coefficients K (rows of the (K, 3) map).
    n_shape, n_albedo, n_expression : int
        Model coefficients sampled.
    directional : bool
        The fit may sample a directional light (five columns at the end; a
        state whose light is off has zeros there, which read back as off).
    """

    n_light: int
    n_shape: int
    n_albedo: int
    n_expression: int
    directional: bool = False

    @classmethod
    def for_params(cls, params: RenderParameter) -> ParamLayout:
        """Return the layout of ``params``' block sizes (directional iff its light is on)."""
        m = params.momo
        return cls(int(np.asarray(params.environment_map.coefficients).shape[0]),
                   len(m.shape), len(m.albedo), len(m.expression),
                   bool(params.directional_light.enabled))

    @property
    def names(self) -> tuple[str, ...]:
        """Column names, in order."""
        light = tuple(f"light.{i}.{c}" for i in range(self.n_light) for c in "rgb")
        return (_POSE + _CAMERA + light + _COLOR_TRANSFORM + ("specular_exponent",)
                + tuple(f"shape.{i}" for i in range(self.n_shape))
                + tuple(f"albedo.{i}" for i in range(self.n_albedo))
                + tuple(f"expression.{i}" for i in range(self.n_expression))
                + (_DIRECTIONAL if self.directional else ()))

    @property
    def size(self) -> int:
        """Number of columns (``len(names)``)."""
        return (7 + 3 + 3 * self.n_light + 7 + 1 + self.n_shape + self.n_albedo + self.n_expression
                + (len(_DIRECTIONAL) if self.directional else 0))

    def index(self, name: str) -> int:
        """Column of ``name``."""
        try:
            return self.names.index(name)
        except ValueError:
            raise InputError(f"no parameter column {name!r}") from None

    def slice(self, block: str) -> slice:
        """Columns of ``"shape"``, ``"albedo"``, ``"expression"`` or ``"light"``."""
        start = 7 + 3
        if block == "light":
            return slice(start, start + 3 * self.n_light)
        start += 3 * self.n_light + 8
        for name, n in (("shape", self.n_shape), ("albedo", self.n_albedo),
                        ("expression", self.n_expression)):
            if block == name:
                return slice(start, start + n)
            start += n
        raise InputError(f"unknown block {block!r}")

    def to_vector(self, params: RenderParameter) -> np.ndarray:
        """(size,) float64 vector of ``params`` (block sizes must match the layout)."""
        p = params
        L = np.asarray(p.environment_map.coefficients, np.float64)
        m = p.momo
        dl = p.directional_light
        if ((L.shape[0], len(m.shape), len(m.albedo), len(m.expression)) != (
                self.n_light, self.n_shape, self.n_albedo, self.n_expression)
                or (dl.enabled and not self.directional)):
            raise InputError("parameters do not match the chain's layout")
        ct = p.color_transform
        return np.concatenate([
            [p.pose.yaw, p.pose.pitch, p.pose.roll, *p.pose.translation, p.pose.scaling,
             p.camera.focal_length, *p.camera.principal_point],
            L.reshape(-1), [*ct.gain, ct.contrast, *ct.offset, p.specular_exponent],
            np.asarray(m.shape, np.float64), np.asarray(m.albedo, np.float64),
            np.asarray(m.expression, np.float64),
            ([*dl.angles(), *dl.diffuse] if dl.enabled else [0.0] * 5) if self.directional else [],
        ])

    def from_vector(self, vector: np.ndarray, template: RenderParameter) -> RenderParameter:
        """Parameters with the sampled fields from ``vector`` and the rest from ``template``."""
        v = np.asarray(vector, np.float64).reshape(-1)
        if v.shape[0] != self.size:
            raise InputError(f"parameter vector has {v.shape[0]} values, layout needs {self.size}")
        f = [float(x) for x in v[:10]]
        pose = template.pose._replace(yaw=f[0], pitch=f[1], roll=f[2],
                                      translation=(f[3], f[4], f[5]), scaling=f[6])
        cam = template.camera._replace(focal_length=f[7], principal_point=(f[8], f[9]))
        i = 10 + 3 * self.n_light
        light = SHLight(v[10:i].reshape(self.n_light, 3).copy())
        c = [float(x) for x in v[i:i + 8]]
        ct = ColorTransform(gain=(c[0], c[1], c[2]), contrast=c[3], offset=(c[4], c[5], c[6]))
        momo = template.momo._replace(shape=v[self.slice("shape")].copy(),
                                      albedo=v[self.slice("albedo")].copy(),
                                      expression=v[self.slice("expression")].copy())
        out = template._replace(pose=pose, camera=cam, environment_map=light,
                                color_transform=ct, specular_exponent=c[7], momo=momo)
        if self.directional:
            d = [float(x) for x in v[-len(_DIRECTIONAL):]]
            out = out._replace(directional_light=DirectionalLight.from_angles(
                d[0], d[1], d[2:], shininess=template.directional_light.shininess))
        return out
