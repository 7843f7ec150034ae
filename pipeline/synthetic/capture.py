"""Capture simulator: a subject in the polarised LED lightstage, three poses, images.

Image formation (camera raw, linear, image values in [0, 1]) at the surface
point ``x`` a pixel sees, with ``v`` the direction to the camera::

    perpendicular = g kappa  t E(x)/E_ref a_d(x)                      + noise
    parallel      = g kappa (t E(x)/E_ref a_d(x) + L_spec(x, v) a_s(x)) + noise
    extra view    = g kappa (  E(x)/E_ref a_d(x) + L_spec(x, v) a_s(x)) + noise

* ``a_d`` (n, 3): the *raw albedo* of a vertex, ``C^T (e * R)`` for skin with
  spectral reflectance ``R(melanin, blood)`` (:mod:`pipeline.synthetic.skin_spectral`)
  under the LED spectrum ``e`` and camera sensitivities ``C``: the simulator
  renders spectrally, folded into one 3-vector per vertex. Eyeballs have no
  spectral model: their raw albedo is ``T^-1`` times their linear sRGB colour.
  Specular reflection of a dielectric does not change the light's spectrum,
  so ``a_s = T^-1 rho_s`` (a grey ``rho_s`` gives a multiple of ``C^T e``).
  With the calibrated transform ``T`` of :mod:`pipeline.lightstage.colour`,
  ``T a_d`` is exactly the subject's linear sRGB diffuse albedo as
  :mod:`pipeline.synthetic.subjects` defines it (up to its lookup-table interpolation,
  < 1e-3) when the capture camera is the default one.
* ``E/E_ref`` and ``L_spec``: :mod:`pipeline.lightstage.dome_shading` (41 point
  LEDs, self-shadowing by occlusion rays when that effect is on).
* ``kappa``: exposure, so that a white diffuser at the dome centre facing the
  photometric camera records ``white_level`` in its brightest raw channel at
  ISO 100 without a filter; ``g``: ISO / 100.
* ``t``: the polarisers' transmission of depolarised (diffuse) light
  (:mod:`pipeline.lightstage.polarisation`); the 7 extra cameras are unfiltered. Their
  images are written as 8-bit gamma-encoded sRGB (``T``, pure 2.2 power), as
  a JPEG camera would.
* noise: Poisson shot noise in photo-electrons plus Gaussian read noise,
  clipping at 1 (saturation), 16-bit quantisation.
* per pose: a small random head rotation and shift, and (misalignment effect)
  a smooth random displacement of the surface, so the three poses do not
  quite agree with the registered mesh.

Images are ray cast through the lens model (:mod:`pipeline.lightstage.camera_render`).
In the photometric views the albedo and the irradiance are interpolated from
the vertices and the specular lobe is evaluated per pixel with the
interpolated normal (highlights are sharper than the mesh); the extra views
interpolate per-vertex radiance (Gouraud). Self-shadowing: LEDs hidden from a
vertex by the mesh (occlusion rays) do not light it.

Effects (:class:`CaptureEffects`) are switches; an effect that is off is not
computed: no specular lobe, no occlusion rays, no noise draws, no
displacement field, no extra-camera renders, zero distortion, ISO 100.

This module imports :mod:`albedo_model`, :mod:`pipeline.lightstage` (``camera_render``,
``colour``, ``dome_shading``, ``polarisation``), :mod:`pipeline.texturing.cameras`,
:mod:`pipeline.synthetic.dome` and :mod:`pipeline.synthetic.skin_spectral`.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.model import vertex_normals
from albedo_model.render.raycast import RayCaster
from pipeline.lightstage.colour import CameraColour
from pipeline.texturing.cameras import LightstageCamera
from pipeline.synthetic.dome import (
    POSES,
    Rig,
    camera_in_mesh_frame,
    pose_transform,
)
from pipeline.lightstage.camera_render import cast_pixels, render_vertex_values
from pipeline.lightstage.dome_shading import LedShading, reference_irradiance
from pipeline.lightstage.polarisation import polarised_pair
from pipeline.synthetic.skin_spectral import skin_reflectance

__all__ = [
    "CaptureEffects", "SimulationSettings", "SubjectCapture", "exposure_constant",
    "misalignment_field", "simulate_capture", "subject_raw_albedo",
]


@dataclasses.dataclass(frozen=True)
class CaptureEffects:
    """Which effects the simulated capture contains (each computed only when on)."""

    specular: bool = True
    shadows: bool = True
    iso_gain: bool = True
    noise: bool = True
    misalignment: bool = True
    multiview: bool = True
    distortion: bool = True

    @classmethod
    def none(cls) -> CaptureEffects:
        """Every effect off: diffuse only, no shadows, ISO 100, exact, aligned, no extras."""
        return cls(**{f.name: False for f in dataclasses.fields(cls)})


@dataclasses.dataclass(frozen=True)
class SimulationSettings:
    """Numbers of the simulated lightstage and sensor.

    Attributes
    ----------
    resolution, extra_resolution : int
        Square image sizes of the photometric and the extra cameras.
    specular_exponent : float
        Blinn-Phong exponent of skin (AlbedoMM's default 20).
    white_level : float
        See the module notes (``kappa``).
    polariser_transmission : float
    full_well : float
        Photo-electrons that fill the sensor (image value 1) at ISO 100; shot
        noise is Poisson in electrons (``value * full_well / g``).
    read_noise : float
        Gaussian read noise std in image units.
    misalignment_mm : float
        RMS length of the per-pose smooth displacement of the surface (3D).
    misalignment_length_mm : float
        Its length scale.
    iso_target : float
        Auto-exposure aims the median face pixel of the parallel image at this
        value, without letting the 99.9th percentile exceed ``0.9``.
    max_iso : int
    boundary_distance_px : float
        Silhouette margin for sampling, written into ``cameras.json``.
    """

    resolution: int = 512
    extra_resolution: int = 384
    specular_exponent: float = 20.0
    white_level: float = 0.5
    polariser_transmission: float = 0.5
    full_well: float = 20000.0
    read_noise: float = 5e-4
    misalignment_mm: float = 0.35
    misalignment_length_mm: float = 40.0
    iso_target: float = 0.25
    max_iso: int = 1600
    boundary_distance_px: float = 12.0


class SubjectCapture(NamedTuple):
    """The simulated capture of one subject.

    Attributes
    ----------
    poses : tuple of str
    cameras : tuple of LightstageCamera
        Photometric camera per pose, world = the registered mesh frame.
    parallel, perpendicular : tuple of (H, W, 3) uint16 arrays
        Linear raw images per pose (value / 65535).
    extra_cameras : tuple of tuples of LightstageCamera
        Per pose, the unpolarised cameras (mesh frame); empty without multiview.
    extra_images : tuple of tuples of (h, w, 3) uint8 arrays
        Gamma-encoded sRGB images of the extra cameras.
    iso : int
    registered : (n, 3) float64
        The subject's mesh in template topology (what template fitting gives).
    """

    poses: tuple[str, ...]
    cameras: tuple[LightstageCamera, ...]
    parallel: tuple[np.ndarray, ...]
    perpendicular: tuple[np.ndarray, ...]
    extra_cameras: tuple[tuple[LightstageCamera, ...], ...]
    extra_images: tuple[tuple[np.ndarray, ...], ...]
    iso: int
    registered: np.ndarray


def subject_raw_albedo(melanin: np.ndarray, blood: np.ndarray, diffuse: np.ndarray,
                       specular: np.ndarray, eyeballs: np.ndarray,
                       colour: CameraColour) -> tuple[np.ndarray, np.ndarray]:
    """Raw diffuse and specular albedo of a subject's vertices (see module notes).

    Parameters
    ----------
    melanin, blood : (n,) float arrays
        Per-vertex fractions (``Subject.melanin``, ``Subject.blood``).
    diffuse, specular : (n, 3) float arrays
        Linear sRGB albedo; ``diffuse`` is used on the eyeballs only.
    eyeballs : (n,) bool array
    colour : CameraColour
        The capture camera under the LED spectrum.

    Returns
    -------
    raw_diffuse, raw_specular : (n, 3) float64
    """
    # the range of pipeline.synthetic.skin_spectral.skin_colour_table, which defines the truth
    refl = skin_reflectance(colour.wavelengths, np.clip(melanin, 0.002, 0.8),
                            np.clip(blood, 0.0, 0.3))
    t_inv = np.linalg.inv(colour.matrix)
    eye = np.asarray(eyeballs, bool)[:, None]
    raw_d = np.where(eye, np.asarray(diffuse, float) @ t_inv.T, colour.raw(refl))
    raw_s = np.asarray(specular, float) @ t_inv.T
    return raw_d, raw_s


def exposure_constant(colour: CameraColour, white_level: float) -> float:
    """``kappa``: image value per unit raw albedo at ``E_ref`` and ISO 100."""
    white = colour.sensitivities.T @ colour.illuminant
    return float(white_level / white.max())


def misalignment_field(vertices: np.ndarray, rng: np.random.Generator, *, rms_mm: float,
                       length_mm: float, n_features: int = 32) -> np.ndarray:
    """Draw a smooth random displacement of the vertices, (n, 3) mm, RMS length ~``rms_mm``.

    Random Fourier features (frequencies ~ N(0, I / length^2)): a draw of a
    Gaussian process with squared-exponential covariance, independent per axis.
    """
    v = np.asarray(vertices, float)
    freq = rng.standard_normal((3, n_features)) / length_mm
    phase = rng.uniform(0.0, 2 * np.pi, n_features)
    amp = rng.standard_normal((n_features, 3)) * rms_mm * np.sqrt(2.0 / (3.0 * n_features))
    return np.cos(v @ freq + phase) @ amp


def _sensor(clean: np.ndarray, gain: float, settings: SimulationSettings,
            rng: np.random.Generator | None) -> np.ndarray:
    """Gain, Poisson-Gaussian noise (only with ``rng``), clipping to [0, 1]."""
    x = clean * gain
    if rng is not None:
        electrons = settings.full_well / gain
        x = rng.poisson(np.maximum(x, 0.0) * electrons) / electrons
        x = x + settings.read_noise * rng.standard_normal(x.shape)
    return np.clip(x, 0.0, 1.0)


def _to_uint16(x: np.ndarray) -> np.ndarray:
    return np.round(x * 65535.0).astype(np.uint16)


def _to_srgb8(raw: np.ndarray, colour: CameraColour, scale: float) -> np.ndarray:
    lin = np.clip((raw / scale) @ colour.matrix.T, 0.0, 1.0)
    return np.round(255.0 * np.exp(np.log(np.maximum(lin, 1e-12)) / 2.2)).astype(np.uint8)


def _auto_iso(clean: list[np.ndarray], coverage: list[np.ndarray],
              settings: SimulationSettings) -> int:
    face = np.concatenate([im[c].ravel() for im, c in zip(clean, coverage)])
    if face.size == 0 or not np.any(face > 0):
        return 100
    k_target = np.floor(np.log2(settings.iso_target / max(np.median(face), 1e-9)))
    k_clip = np.floor(np.log2(0.9 / max(np.percentile(face, 99.9), 1e-9)))
    k = int(np.clip(min(k_target, k_clip), 0, np.log2(settings.max_iso / 100.0)))
    return 100 * 2**k


def simulate_capture(
    vertices: np.ndarray, triangles: np.ndarray, raw_diffuse: np.ndarray,
    raw_specular: np.ndarray, *, rig: Rig, colour: CameraColour,
    settings: SimulationSettings | None = None,
    effects: CaptureEffects | None = None, rng: np.random.Generator,
) -> SubjectCapture:
    """Simulate the three-pose polarised capture of one subject.

    Parameters
    ----------
    vertices : (n, 3) float array
        The subject's surface (mesh frame, mm); also returned as the registration.
    triangles : (m, 3) int array
    raw_diffuse, raw_specular : (n, 3) float arrays
        Raw albedo (:func:`subject_raw_albedo`).
    rig : Rig
        Must match ``effects.distortion`` and the settings' resolutions
        (:func:`pipeline.synthetic.dome.build_rig`).
    colour : CameraColour
        The capture camera (extra images are encoded with its transform).
    settings : SimulationSettings, optional
    effects : CaptureEffects, optional
        Default: every effect on.
    rng : numpy Generator
        Pose jitter, misalignment and noise are drawn from it.

    Returns
    -------
    SubjectCapture
    """
    settings = SimulationSettings() if settings is None else settings
    effects = CaptureEffects() if effects is None else effects
    v = np.asarray(vertices, float)
    tri = np.asarray(triangles)
    a_d = np.asarray(raw_diffuse, float)
    a_s = np.asarray(raw_specular, float)
    if a_d.shape != v.shape or a_s.shape != v.shape:
        raise InputError(f"raw albedo {a_d.shape}, {a_s.shape} must match vertices {v.shape}")
    kappa = exposure_constant(colour, settings.white_level)
    e_ref = reference_irradiance(rig.leds, np.zeros(3), rig.photometric.centre)
    cams, clean_pairs, coverages, extra_cams, extra_clean = [], [], [], [], []
    for pose_name in POSES:
        pose = pose_transform(pose_name, rng)
        posed = v
        if effects.misalignment:
            posed = v + misalignment_field(v, rng, rms_mm=settings.misalignment_mm,
                                           length_mm=settings.misalignment_length_mm)
        v_rig = pose.apply(posed)
        normals = vertex_normals(v_rig, tri)
        caster = RayCaster(v_rig, tri)
        shading = LedShading(v_rig, normals, rig.leds, reference=e_ref,
                             caster=caster if effects.shadows else None)
        irradiance = shading.irradiance()
        hits = cast_pixels(rig.photometric, caster, tri)
        irr_px, lobe_px, *_ = shading.at_pixels(
            hits, rig.photometric.centre, settings.specular_exponent if effects.specular else None)
        diffuse_px = kappa * irr_px[:, None] * hits.interpolate(a_d)
        spec_img = None
        if effects.specular:
            spec_img = hits.image(kappa * lobe_px[:, None] * hits.interpolate(a_s))
        para, perp = polarised_pair(hits.image(diffuse_px), spec_img,
                                    transmission=settings.polariser_transmission)
        cov = hits.coverage()
        cams.append(camera_in_mesh_frame(rig.photometric, pose))
        clean_pairs.append((para, perp))
        coverages.append(cov)
        if effects.multiview:
            views = []
            diffuse = kappa * irradiance[:, None] * a_d
            for cam in rig.extra:
                rad = diffuse
                if effects.specular:
                    lobe = shading.specular(cam.centre, settings.specular_exponent)
                    rad = diffuse + kappa * lobe[:, None] * a_s
                views.append(render_vertex_values(cam, caster, tri, rad)[0])
            extra_clean.append(views)
            extra_cams.append(tuple(camera_in_mesh_frame(c, pose) for c in rig.extra))
    iso = (_auto_iso([p for p, _ in clean_pairs], coverages, settings)
           if effects.iso_gain else 100)
    gain = iso / 100.0
    noise_rng = rng if effects.noise else None
    para_out = tuple(_to_uint16(_sensor(p, gain, settings, noise_rng)) for p, _ in clean_pairs)
    perp_out = tuple(_to_uint16(_sensor(q, gain, settings, noise_rng)) for _, q in clean_pairs)
    extra_out = tuple(
        tuple(_to_srgb8(_sensor(im, gain, settings, noise_rng), colour, gain * kappa)
              for im in views) for views in extra_clean)
    return SubjectCapture(POSES, tuple(cams), para_out, perp_out, tuple(extra_cams), extra_out,
                          iso, v.copy())
