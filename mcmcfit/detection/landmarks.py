"""Basel-named landmarks of a photograph, detected with MediaPipe Face Mesh.

:func:`detect_landmarks` runs Face Mesh, picks a face (the largest, or the
``face``-th by size), reads the Basel points of :data:`~mcmcfit.detection.basel_names.BASEL_POINTS`
and judges the detection. Face Mesh always returns a whole mesh, also for the
side of the face turned away from the camera, and visibly wrong meshes near
90 deg profiles; so the head's yaw is estimated from the mesh's own depth (the
line between the outer eye corners), the far side's points are dropped beyond
:data:`FAR_SIDE_YAW_DEG`, and a detection beyond :data:`PROFILE_YAW_DEG` is
flagged as low confidence.

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.io.tlms` and
:mod:`mcmcfit.detection` (face_mesh, basel_names).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.tlms import Landmark
from mcmcfit.detection.basel_names import BASEL_POINTS
from mcmcfit.detection.face_mesh import face_meshes

__all__ = ["FAR_SIDE_YAW_DEG", "PROFILE_YAW_DEG", "Detection", "detect_landmarks"]

#: Beyond this yaw the points of the side turned away are dropped (hidden or guessed).
FAR_SIDE_YAW_DEG = 35.0
#: Beyond this yaw the detection is flagged as low confidence (Face Mesh fails near 90 deg).
PROFILE_YAW_DEG = 60.0


class Detection(NamedTuple):
    """Landmarks detected in one photograph.

    Attributes
    ----------
    landmarks : list of Landmark
        Basel-named 2-D points in pixels (x right, y down).
    sigma_factors : dict name -> float
        Per-point reliability: multiplies the fit's landmark sigma.
    face : int
        Which face (0: the largest).
    n_faces : int
        Faces found.
    box : (x0, y0, x1, y1)
        Bounding box of the face's mesh in pixels.
    yaw_deg : float
        Yaw estimated from the mesh (positive: the subject's left turned away).
    dropped : tuple of str
        Names dropped as far-side points.
    low_confidence : bool
        True near profile (``|yaw| > PROFILE_YAW_DEG``): check the points.
    mesh : (468, 3) float64
        The chosen face's whole mesh (pixels).
    """

    landmarks: list[Landmark]
    sigma_factors: dict[str, float]
    face: int
    n_faces: int
    box: tuple[float, float, float, float]
    yaw_deg: float
    dropped: tuple[str, ...]
    low_confidence: bool
    mesh: np.ndarray

    def points(self) -> dict[str, tuple[float, float]]:
        """Return the landmarks as a mapping name -> (x, y)."""
        return {lm.name: (float(lm.point[0]), float(lm.point[1])) for lm in self.landmarks}

    def summary(self) -> dict:
        """Return a JSON-able description (without the mesh) for ``summary.json``."""
        return {"method": "mediapipe-face-mesh", "face": self.face, "n_faces": self.n_faces,
                "box": [float(v) for v in self.box], "yaw_deg": float(self.yaw_deg),
                "dropped": list(self.dropped), "low_confidence": bool(self.low_confidence),
                "sigma_factors": dict(self.sigma_factors)}


def _yaw_deg(mesh: np.ndarray) -> float:
    """Yaw of the head from the outer eye corners' depth: 0 frontal, > 0 left side away."""
    right, left = mesh[33], mesh[263]  # subject's right / left outer eye corner
    dx, dz = left[0] - right[0], left[2] - right[2]
    return math.degrees(math.atan2(dz, dx))


def detect_landmarks(image: np.ndarray, *, face: int | None = None,
                     max_faces: int = 5) -> Detection:
    """Detect Basel-named landmarks in a photograph.

    Parameters
    ----------
    image : (H, W, 3) array
        The photograph (uint8, or floats in [0, 1] as :func:`~albedo_model.io.image_io.read_image`
        returns them).
    face : int, optional
        Which face when several are found, by size (0: the largest, the default).
    max_faces : int
        Faces looked for at most.

    Returns
    -------
    Detection

    Raises
    ------
    InputError
        The ``landmarks`` extra is not installed, no face is found, or ``face`` is
        not among the faces found.
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] < 3:
        raise InputError(f"landmark detection needs an (H, W, 3) colour image, got {img.shape}")
    meshes = face_meshes(img, max_faces=max(int(max_faces), (face or 0) + 1))
    if meshes.shape[0] == 0:
        raise InputError("no face found in the image (pass --landmarks or --face-box to place "
                         "it by hand)")
    extent = meshes[:, :, :2].max(axis=1) - meshes[:, :, :2].min(axis=1)
    order = np.argsort(-(extent[:, 0] * extent[:, 1]), kind="stable")
    k = 0 if face is None else int(face)
    if not 0 <= k < len(order):
        raise InputError(f"--face {k}: only {len(order)} face(s) found (0 is the largest)")
    mesh = meshes[order[k]]
    yaw = _yaw_deg(mesh)
    far = "left" if yaw > 0 else "right"
    drop = abs(yaw) > FAR_SIDE_YAW_DEG
    h, w = img.shape[:2]
    landmarks, factors, dropped = [], {}, []
    for point in BASEL_POINTS:
        x, y = mesh[point.index, 0], mesh[point.index, 1]
        if drop and point.name.startswith(far + "."):
            dropped.append(point.name)
            continue
        if not (np.isfinite(x) and np.isfinite(y)) or not (0 <= x < w and 0 <= y < h):
            dropped.append(point.name)
            continue
        landmarks.append(Landmark(point.name, (float(x), float(y)), True))
        factors[point.name] = point.sigma_factor
    lo, hi = mesh[:, :2].min(axis=0), mesh[:, :2].max(axis=0)
    return Detection(landmarks, factors, k, int(meshes.shape[0]),
                     (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])), float(yaw),
                     tuple(dropped), abs(yaw) > PROFILE_YAW_DEG, mesh)
