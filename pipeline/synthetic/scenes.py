"""Scenes of the held-out evaluation: what each photograph has that the fit's image model lacks.

A :class:`SceneSpec` lists every effect of the photograph, each switchable:
the light (the fit's SH light, an extra scalismo directional light, its cast
shadows), the specular term, the camera (an unknown 3x3 white-balance matrix
near identity, sensor read and shot noise, 8-bit quantisation, JPEG), the
head's yaw, which subjects (Fitzpatrick types), the background and the
landmark noise. :data:`SCENES` holds the evaluation's scenes:

``sh``
    In-model control: SH light (ambient + a directional lobe), specular,
    small white sensor noise, 8-bit PNG. Only the albedo (a held-out subject)
    is out of the model.
``ambient``
    The paper's protocol: near-ambient camera light with a weak directional
    part, specular on, read and shot noise, JPEG, a white-balance error.
``directional``
    ``ambient`` plus one directional light from the side with cast shadows
    (ray-cast with Embree).
``profile``
    ``ambient`` with the head turned 45-70 degrees.
``dark``
    ``ambient`` on the Fitzpatrick V-VI subjects only.

:func:`scene_spec` returns one of them with effects overridden.

This module imports :mod:`albedo_model.errors` only.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from albedo_model.errors import InputError

__all__ = ["SCENES", "SceneSpec", "scene_spec"]


@dataclass(frozen=True)
class SceneSpec:
    """Every effect of one scene (each switchable).

    Attributes
    ----------
    name : str
    ambient : float
        SH band-0 light (uniform irradiance factor).
    sh_directional : float
        Strength of the SH light's directional lobe (band 1; inside the fit's model).
    directional : float
        Strength of an extra scalismo directional light (0: none).
    directional_azimuth_deg : float
        Its angle from the view direction, towards the subject's side (sign drawn).
    shadows : bool
        Cast shadows of the directional light (occlusion rays).
    specular : bool
        Render the specular term.
    white_balance_sd : float
        Sd of the entries of the unknown colour matrix ``I + E`` (0: none).
    read_noise : float
        Sd of the sensor read noise (linear units; 0: none).
    shot_noise : float
        Photon noise: variance ``shot_noise * value`` (linear; 0: none).
    jpeg_quality : int or None
        JPEG quality of the written photograph (None: lossless PNG).
    yaw_deg : (float, float)
        Range of the absolute head yaw (sign drawn).
    fitzpatrick : tuple of int
        Skin types of the subjects photographed in this scene.
    background : {"textured", "flat"}
    landmark_noise_px : float
        Sd of the landmark noise at 250 px (scaled with the image size).
    """

    name: str
    ambient: float = 0.85
    sh_directional: float = 0.15
    directional: float = 0.0
    directional_azimuth_deg: float = 65.0
    shadows: bool = False
    specular: bool = True
    white_balance_sd: float = 0.04
    read_noise: float = 0.004
    shot_noise: float = 0.0004
    jpeg_quality: int | None = 85
    yaw_deg: tuple = (0.0, 25.0)
    fitzpatrick: tuple = (1, 2, 3, 4, 5, 6)
    background: str = "textured"
    landmark_noise_px: float = 1.5

    def effects(self) -> list[str]:
        """Return the names of the out-of-model effects this scene computes."""
        out = []
        if self.directional > 0:
            out.append("directional light")
            if self.shadows:
                out.append("cast shadows")
        if self.white_balance_sd > 0:
            out.append("white balance")
        if self.shot_noise > 0:
            out.append("shot noise")
        if self.jpeg_quality is not None:
            out.append("JPEG")
        return out

    def to_dict(self) -> dict:
        """Return the fields as a plain dict (JSON)."""
        return dataclasses.asdict(self)


_AMBIENT = SceneSpec("ambient")

#: The evaluation's scenes by name.
SCENES = {
    "sh": SceneSpec("sh", ambient=0.7, sh_directional=0.4, white_balance_sd=0.0,
                    read_noise=0.008, shot_noise=0.0, jpeg_quality=None),
    "ambient": _AMBIENT,
    "directional": dataclasses.replace(_AMBIENT, name="directional", ambient=0.45,
                                       sh_directional=0.1, directional=0.9, shadows=True),
    "profile": dataclasses.replace(_AMBIENT, name="profile", yaw_deg=(45.0, 70.0)),
    "dark": dataclasses.replace(_AMBIENT, name="dark", fitzpatrick=(5, 6)),
}


def scene_spec(name: str, **overrides) -> SceneSpec:
    """Return scene ``name`` of :data:`SCENES` with ``overrides`` applied.

    Raises
    ------
    InputError
        Unknown scene or field.
    """
    if name not in SCENES:
        raise InputError(f"unknown scene {name!r}; use one of {', '.join(SCENES)}")
    fields = {f.name for f in dataclasses.fields(SceneSpec)}
    bad = sorted(set(overrides) - fields)
    if bad:
        raise InputError(f"unknown scene field(s) {', '.join(bad)}")
    return dataclasses.replace(SCENES[name], **overrides)
