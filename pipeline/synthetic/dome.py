"""Geometry of the synthetic lightstage: LED dome, cameras and the three capture poses.

Rig frame (mm): origin at the dome centre, +y up, +z towards the photometric
camera (the subject faces +z in the frontal pose). Smith et al. 2020 describe
41 white LEDs on a geodesic dome of 1.8 m diameter ("a once-subdivided
icosahedron": 42 vertices, the lowest one left out), one photometric camera
near the equator with the polariser pair, and 7 unpolarised cameras giving
overlapping multiview coverage. The subject is captured in three poses:
frontal and the two profiles.

A pose places the subject's registered mesh in the rig, ``X_rig = R (X - c) + t``
with ``c`` the head's pivot. Cameras here are :class:`LightstageCamera` objects
whose world is the rig; :func:`camera_in_mesh_frame` re-expresses a camera in the
mesh frame of one pose (what a capture's ``cameras.json`` stores, as
structure-from-motion would give it).

Imports only :mod:`albedo_model.errors` and :mod:`pipeline.texturing.cameras`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np

from albedo_model.errors import InputError
from pipeline.texturing.cameras import LightstageCamera

__all__ = [
    "DOME_RADIUS_MM", "POSES", "PoseTransform", "Rig", "build_rig", "camera_in_mesh_frame",
    "dome_leds", "look_at_camera", "pose_transform",
]

DOME_RADIUS_MM = 900.0
#: Capture poses in order; the first is the stitching reference.
POSES = ("frontal", "left", "right")
#: Yaw of each pose (radians, about +y): "left" turns the subject's left cheek (+x) to the camera.
_POSE_YAW = {"frontal": 0.0, "left": np.deg2rad(-70.0), "right": np.deg2rad(70.0)}
#: Rotation pivot of the head in the template frame (mm).
HEAD_PIVOT_MM = np.array([0.0, 20.0, 10.0])
#: (azimuth, elevation) in degrees of the 7 unpolarised cameras.
_EXTRA_CAMERAS = ((-35.0, 15.0), (35.0, 15.0), (-62.0, -5.0), (62.0, -5.0), (0.0, 38.0),
                  (-22.0, -24.0), (22.0, -24.0))
_PHOTOMETRIC_ELEVATION_DEG = 4.0
_CAMERA_DISTANCE_MM = 880.0
#: Field of view (mm across the image at the dome centre) of all cameras.
_FIELD_MM = 300.0
#: Lens distortion (k1, k2, k3, p1, p2) used when the distortion effect is on.
_PHOTOMETRIC_DISTORTION = (-0.06, 0.02, 0.0, 2e-4, -1e-4)


def dome_leds(radius_mm: float = DOME_RADIUS_MM) -> np.ndarray:
    """Return the LED positions, (41, 3) mm in the rig frame.

    The LEDs sit on a once-subdivided icosahedron without its lowest vertex.

    One icosahedron vertex points straight down (-y) and is left out (the
    subject sits there); the dome keeps the 11 other vertices and the 30 edge
    midpoints, all projected onto the sphere of ``radius_mm``.
    """
    phi = (1.0 + np.sqrt(5.0)) / 2.0
    base = []
    for a in (-1.0, 1.0):
        for b in (-phi, phi):
            base += [(0.0, a, b), (a, b, 0.0), (b, 0.0, a)]
    v = np.array(base) / np.linalg.norm(base[0])
    # rotate the vertex (0, -1, -phi)/|.| onto -y
    bottom = v[np.argmin(v[:, 1] - 1e-9 * v[:, 2])]
    axis = np.cross(bottom, [0.0, -1.0, 0.0])
    s, c = np.linalg.norm(axis), float(bottom @ np.array([0.0, -1.0, 0.0]))
    k = axis / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    rot = np.eye(3) + s * kx + (1 - c) * kx @ kx
    v = v @ rot.T
    edge = np.min([np.linalg.norm(v[0] - w) for w in v[1:]])
    mids = []
    for i in range(12):
        for j in range(i + 1, 12):
            if np.linalg.norm(v[i] - v[j]) < edge * 1.01:
                m = v[i] + v[j]
                mids.append(m / np.linalg.norm(m))
    pts = np.vstack([v, mids])
    pts = pts[np.argsort(pts[:, 1])][1:]  # drop the lowest
    return radius_mm * pts


def look_at_camera(centre: np.ndarray, target: np.ndarray, *, focal_px: float,
                   image_size: tuple[int, int],
                   distortion: tuple[float, ...] = (0.0,) * 5) -> LightstageCamera:
    """Make a camera at ``centre`` looking at ``target``, +y up in the image (world -> camera).

    Parameters
    ----------
    centre, target : (3,) float arrays, world frame
    focal_px : float
    image_size : (height, width)
    distortion : (k1, k2, k3, p1, p2)
    """
    c = np.asarray(centre, float)
    forward = np.asarray(target, float) - c
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    if np.linalg.norm(right) < 1e-9:
        raise InputError("look_at_camera: viewing direction is vertical")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rot = np.stack([right, down, forward])
    h, w = (int(x) for x in image_size)
    return LightstageCamera(rotation=rot, translation=-rot @ c, focal_px=float(focal_px),
                            principal_px=np.array([(w - 1) / 2.0, (h - 1) / 2.0]),
                            image_size=(h, w), distortion=np.asarray(distortion, float))


def _on_dome(azimuth_deg: float, elevation_deg: float, distance: float) -> np.ndarray:
    az, el = np.deg2rad(azimuth_deg), np.deg2rad(elevation_deg)
    return distance * np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])


@dataclasses.dataclass(frozen=True, eq=False)
class Rig:
    """The lightstage in its own frame.

    Attributes
    ----------
    leds : (L, 3) float64
        LED positions, rig frame, mm.
    photometric : LightstageCamera
        The polarisation-calibrated camera (world = rig).
    extra : tuple of LightstageCamera
        The unpolarised multiview cameras (world = rig).
    """

    leds: np.ndarray
    photometric: LightstageCamera
    extra: tuple[LightstageCamera, ...]

    def leds_in_camera_frame(self) -> np.ndarray:
        """(L, 3) LED positions in the photometric camera's frame (mm)."""
        return self.photometric.to_camera(self.leds)


def build_rig(*, resolution: int = 512, extra_resolution: int = 384,
              distortion: bool = False) -> Rig:
    """Build the synthetic lightstage.

    Parameters
    ----------
    resolution : int
        Photometric images are ``resolution x resolution`` pixels.
    extra_resolution : int
        Multiview images are ``extra_resolution`` square.
    distortion : bool
        Give the cameras lens distortion (the photometric one
        ``_PHOTOMETRIC_DISTORTION``, the others a milder barrel).
    """
    if resolution < 16 or extra_resolution < 16:
        raise InputError("image resolutions must be at least 16 pixels")
    target = np.zeros(3)
    zero = (0.0,) * 5
    photo = look_at_camera(
        _on_dome(0.0, _PHOTOMETRIC_ELEVATION_DEG, _CAMERA_DISTANCE_MM), target,
        focal_px=resolution * _CAMERA_DISTANCE_MM / _FIELD_MM, image_size=(resolution, resolution),
        distortion=_PHOTOMETRIC_DISTORTION if distortion else zero)
    extra = tuple(
        look_at_camera(_on_dome(az, el, _CAMERA_DISTANCE_MM), target,
                       focal_px=extra_resolution * _CAMERA_DISTANCE_MM / _FIELD_MM,
                       image_size=(extra_resolution, extra_resolution),
                       distortion=(-0.03, 0.0, 0.0, 0.0, 0.0) if distortion else zero)
        for az, el in _EXTRA_CAMERAS)
    return Rig(dome_leds(), photo, extra)


@dataclasses.dataclass(frozen=True)
class PoseTransform:
    """``X_rig = rotation @ X_mesh + translation`` (mm)."""

    rotation: np.ndarray
    translation: np.ndarray

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) rig-frame positions of mesh-frame points."""
        return np.asarray(points, float) @ self.rotation.T + self.translation

    def apply_direction(self, vectors: np.ndarray) -> np.ndarray:
        """(n, 3) rig-frame directions of mesh-frame directions."""
        return np.asarray(vectors, float) @ self.rotation.T


def _rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    cy, sy, cp, sp_, cr, sr = (np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch),
                               np.cos(roll), np.sin(roll))
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cp, -sp_], [0, sp_, cp]])
    rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    return ry @ rx @ rz


def pose_transform(pose: str, rng: np.random.Generator | None = None, *,
                   jitter_deg: float = 3.0, jitter_mm: float = 4.0) -> PoseTransform:
    """Where the subject's mesh sits in the rig for one capture pose.

    Parameters
    ----------
    pose : {"frontal", "left", "right"}
    rng : numpy Generator, optional
        Draws a small random head rotation (``jitter_deg`` std per axis) and
        shift (``jitter_mm`` std per axis); none without a generator.
    """
    if pose not in _POSE_YAW:
        raise InputError(f"unknown pose {pose!r}; use one of {', '.join(POSES)}")
    angles = np.array([_POSE_YAW[pose], 0.0, 0.0])
    shift = np.zeros(3)
    if rng is not None:
        angles += np.deg2rad(jitter_deg) * rng.standard_normal(3)
        shift = jitter_mm * rng.standard_normal(3)
    rot = _rotation(*angles)
    return PoseTransform(rot, shift - rot @ HEAD_PIVOT_MM)


def camera_in_mesh_frame(camera: LightstageCamera, pose: PoseTransform) -> LightstageCamera:
    """Return the rig camera re-expressed with the posed mesh's frame as world."""
    return replace(camera, rotation=camera.rotation @ pose.rotation,
                   translation=camera.rotation @ pose.translation + camera.translation)
