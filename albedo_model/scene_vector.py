"""All continuous scene parameters as one flat vector (:class:`SceneLayout`).

The vector is what the pixel Jacobian (:mod:`albedo_model.render.jacobian`)
differentiates in and what the Gaussian moves' coordinates
(:mod:`proposals.laplace.coordinates`) are built on.

This module imports :mod:`albedo_model.errors` and :mod:`albedo_model.params`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.params import ColorTransform, DirectionalLight, RenderParameter, SHLight

__all__ = ["ENTRIES", "SceneLayout"]

#: The entries of a :class:`SceneLayout` vector, in order (sizes in :meth:`SceneLayout.sizes`).
ENTRIES = ("shape", "expression", "angles", "translation", "focal_length", "principal_point",
           "light", "gain", "contrast", "offset", "specular_exponent", "albedo",
           "light_angles", "light_intensity")


class SceneLayout(NamedTuple):
    """A flat vector of every continuous scene parameter, for given coefficient counts.

    ==================  ====  ===================================================
    entry               size  content
    ==================  ====  ===================================================
    shape               ks    ``momo.shape`` (prior sds)
    expression          ke    ``momo.expression``
    angles              3     yaw, pitch, roll (rad)
    translation         3     pose translation (mm)
    focal_length        1     camera focal length (sensor units)
    principal_point     2     principal point (NDC)
    light               3 K   SH coefficients, row-major (K, 3)
    gain, contrast,     3,1,3 colour transform
    offset
    specular_exponent   1
    albedo              ka    ``momo.albedo`` (shared diffuse/specular coefficients)
    light_angles        2/0   the directional light's azimuth and elevation (rad,
                              :meth:`~albedo_model.params.DirectionalLight.angles`)
    light_intensity     3/0   its RGB strength (diffuse = specular)
    ==================  ====  ===================================================

    The directional light's entries are empty unless ``directional``; with them,
    :meth:`with_vector` writes a light without ambient term whose specular colour
    is its diffuse colour, keeping the template's shininess. The angles' chart
    is ``|az| < pi``, ``|el| < pi/2`` (the sphere but a seam): a vector outside
    it gets a NaN strength, which the prior gives density 0, so a move across
    the seam is rejected rather than re-expressed (which would break the
    reversibility of moves drawn in these coordinates).
    """

    n_shape: int
    n_expression: int
    n_light: int
    n_albedo: int
    directional: bool = False

    @classmethod
    def for_params(cls, params: RenderParameter) -> SceneLayout:
        """Return the layout of ``params``' coefficient counts (directional iff its light is on)."""
        return cls(len(params.momo.shape), len(params.momo.expression),
                   int(np.asarray(params.environment_map.coefficients).shape[0]),
                   len(params.momo.albedo), bool(params.directional_light.enabled))

    def sizes(self) -> dict[str, int]:
        """Entry name -> size, in vector order."""
        return {"shape": self.n_shape, "expression": self.n_expression, "angles": 3,
                "translation": 3, "focal_length": 1, "principal_point": 2,
                "light": 3 * self.n_light, "gain": 3, "contrast": 1, "offset": 3,
                "specular_exponent": 1, "albedo": self.n_albedo,
                "light_angles": 2 if self.directional else 0,
                "light_intensity": 3 if self.directional else 0}

    def slices(self) -> dict[str, slice]:
        """Entry name -> its slice of the vector."""
        out, start = {}, 0
        for name, n in self.sizes().items():
            out[name] = slice(start, start + n)
            start += n
        return out

    @property
    def size(self) -> int:
        """Length of the vector."""
        return sum(self.sizes().values())

    def vector(self, params: RenderParameter) -> np.ndarray:
        """Return the (size,) float64 vector of ``params``."""
        p, ct = params, params.color_transform
        if SceneLayout.for_params(p) != self:
            raise InputError("parameters do not match the scene layout")
        parts = (p.momo.shape, p.momo.expression, (p.pose.yaw, p.pose.pitch, p.pose.roll),
                 p.pose.translation, (p.camera.focal_length,), p.camera.principal_point,
                 np.asarray(p.environment_map.coefficients).reshape(-1), ct.gain,
                 (ct.contrast,), ct.offset, (p.specular_exponent,), p.momo.albedo)
        if self.directional:
            parts += (p.directional_light.angles(), p.directional_light.diffuse)
        return np.concatenate([np.asarray(v, np.float64).reshape(-1) for v in parts])

    def with_vector(self, params: RenderParameter, x: np.ndarray) -> RenderParameter:
        """Return ``params`` with every entry of the layout taken from ``x``."""
        x = np.asarray(x, np.float64).reshape(-1)
        if x.shape[0] != self.size:
            raise InputError(f"scene vector has {x.shape[0]} entries, the layout {self.size}")
        s = {k: x[v] for k, v in self.slices().items()}

        def floats(name):
            return tuple(float(v) for v in s[name])

        p = params
        a, t = floats("angles"), floats("translation")
        if self.directional:
            az, el = floats("light_angles")
            strength = floats("light_intensity")
            if not (abs(az) < np.pi and abs(el) < 0.5 * np.pi):
                strength = (np.nan,) * 3  # outside the angles' chart: the prior rejects it
            light = DirectionalLight.from_angles(az, el, strength,
                                                 shininess=p.directional_light.shininess)
            if (az, el) == p.directional_light.angles():
                # the same angles keep the very direction vector (not its round trip through
                # the angles), so a strength move leaves the cast shadows' block untouched
                light = light._replace(direction=p.directional_light.direction)
            p = p._replace(directional_light=light)
        return p._replace(
            pose=p.pose._replace(yaw=a[0], pitch=a[1], roll=a[2], translation=t),
            camera=p.camera._replace(focal_length=float(s["focal_length"][0]),
                                     principal_point=floats("principal_point")),
            environment_map=SHLight(s["light"].reshape(self.n_light, 3).copy()),
            color_transform=ColorTransform(gain=floats("gain"),
                                           contrast=float(s["contrast"][0]),
                                           offset=floats("offset")),
            specular_exponent=float(s["specular_exponent"][0]),
            momo=p.momo._replace(shape=s["shape"].copy(), expression=s["expression"].copy(),
                                 albedo=s["albedo"].copy()))
