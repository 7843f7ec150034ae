"""Automatic landmarks: MediaPipe Face Mesh on a photograph, mapped to Basel landmark names.

Modules
-------
face_mesh
    The optional MediaPipe runtime (extra ``mcmcfit[landmarks]``): 468 mesh points per
    face, in pixels; a clear error when the extra is not installed.
basel_names
    Which mesh point is which Basel landmark, and how reliable each is (per-point sigma).
landmarks
    :func:`~mcmcfit.detection.landmarks.detect_landmarks`: choose the face, estimate its
    yaw, drop far-side points near profile, return Basel-named landmarks.
overlay
    A picture of the detected landmarks over the photograph.

Imports :mod:`albedo_model` (errors, io) only.
"""
