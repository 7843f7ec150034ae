"""Calibrated lightstage cameras: pinhole projection with lens distortion, and their JSON files.

Model (world = the registered mesh's frame, any length unit)::

    X_c = R X + t                                   world -> camera, camera looks down +z
    x = X_c / Z_c,  y = Y_c / Z_c,  r2 = x^2 + y^2
    radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
    x_d = x radial + 2 p1 x y + p2 (r2 + 2 x^2)     (OpenCV's p1, p2)
    y_d = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
    u = cx + f x_d,  v = cy + f y_d                 pixels, x right, y down

Pixel coordinates here are 0-based like the rest of the project: the pixel in
row ``r`` and column ``c`` (both counted from 0) is centred at ``(u, v) = (c, r)``
(scalismo's "pixel (i, j) is the continuous point (i, j)").

Camera file (JSON; ``cameras.json`` of the AlbedoMM sample is an instance)::

    {"intrinsics": {"w": W, "h": H, "f": px, "cx": px, "cy": px,
                    "k1": 0, "k2": 0, "k3": 0, "p1": 0, "p2": 0,      # optional, default 0
                    "tangential": "matlabrenderer" | "opencv",        # optional
                    "pixel_origin": 1 | 0},                           # optional
     "views": [{"image": "im1.jpg", "T": 4x4 or 3x4 row-major world->camera,
                "intrinsics": {...}}, ...],                            # per-view override
     "stitching": {"boundary_distance_px": 100, "lambda": 0.1,
                   "reference_view": 0}}                               # optional

The defaults follow the MatlabRenderer convention of the published AlbedoMM
demo: ``cx, cy`` are 1-based pixel coordinates (``pixel_origin`` 1) and its
``p1, p2`` are OpenCV's ``p2, p1`` (``tangential`` "matlabrenderer"; the loader
swaps them). Files from OpenCV calibrations set ``"pixel_origin": 0`` and
``"tangential": "opencv"``. A view's own ``intrinsics`` block overrides single
fields of the shared one (cameras that refocus between captures).

Imports only :mod:`albedo_model.errors` and :mod:`pipeline.texturing.json_files`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from albedo_model.errors import FormatError, InputError
from pipeline.texturing.json_files import read_json_file

__all__ = ["LightstageCamera", "LightstageRig", "StitchSettings", "load_cameras", "rig_from_dict"]

_DISTORTION = ("k1", "k2", "k3", "p1", "p2")


@dataclass(frozen=True, eq=False)
class LightstageCamera:
    """A pinhole camera with Brown-Conrady distortion (OpenCV's 5-parameter model).

    Attributes
    ----------
    rotation : (3, 3) float64
        World -> camera rotation ``R``.
    translation : (3,) float64
        World -> camera translation ``t`` (world units).
    focal_px : float
        Focal length in pixels (square pixels).
    principal_px : (2,) float64
        ``(cx, cy)``, 0-based pixel coordinates.
    image_size : (int, int)
        ``(height, width)`` in pixels.
    distortion : (5,) float64
        ``(k1, k2, k3, p1, p2)`` with OpenCV's meaning of ``p1, p2``.
    """

    rotation: np.ndarray
    translation: np.ndarray
    focal_px: float
    principal_px: np.ndarray
    image_size: tuple[int, int]
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(5))

    def __post_init__(self) -> None:
        """Validate the fields and store them as read-only float64 arrays and plain numbers."""
        for name, shape in (("rotation", (3, 3)), ("translation", (3,)),
                            ("principal_px", (2,)), ("distortion", (5,))):
            a = np.array(getattr(self, name), dtype=np.float64)
            if a.shape != shape or not np.isfinite(a).all():
                raise InputError(f"camera {name} must be a finite array of shape {shape}")
            a.flags.writeable = False
            object.__setattr__(self, name, a)
        h, w = (int(x) for x in self.image_size)
        if h < 1 or w < 1 or not self.focal_px > 0:
            raise InputError("camera image size and focal length must be positive")
        object.__setattr__(self, "image_size", (h, w))
        object.__setattr__(self, "focal_px", float(self.focal_px))

    @property
    def centre(self) -> np.ndarray:
        """(3,) float64: the camera centre ``-R^T t`` in world coordinates."""
        return -self.rotation.T @ self.translation

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) float64 camera coordinates ``R X + t`` of world points (n, 3)."""
        return np.asarray(points, np.float64) @ self.rotation.T + self.translation

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Distorted normalised coordinates of undistorted ones (both (n, 2) float64)."""
        k1, k2, k3, p1, p2 = self.distortion
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xy2 = 2.0 * x * y
        return np.stack([x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x),
                         y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2], axis=1)

    def undistort(self, xy_d: np.ndarray, *, iterations: int = 20,
                  tol: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
        """Invert :meth:`distort` by fixed-point iteration.

        Parameters
        ----------
        xy_d : (n, 2) float array, distorted normalised coordinates
        iterations : int
        tol : float
            Convergence threshold on the re-distortion error (normalised units).

        Returns
        -------
        xy : (n, 2) float64
            Undistorted normalised coordinates.
        converged : (n,) bool
            False where the polynomial does not invert (far outside the calibrated
            field, where the distortion folds over).
        """
        xy_d = np.asarray(xy_d, np.float64)
        k1, k2, k3, p1, p2 = self.distortion
        xy = xy_d.copy()
        for _ in range(iterations):
            x, y = xy[:, 0], xy[:, 1]
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
            dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                xy = np.stack([(xy_d[:, 0] - dx) / radial, (xy_d[:, 1] - dy) / radial], axis=1)
        with np.errstate(invalid="ignore", over="ignore"):
            err = np.abs(self.distort(xy) - xy_d).max(axis=1)
        converged = np.isfinite(err) & (err <= tol * np.maximum(1.0, np.abs(xy_d).max(axis=1)))
        return xy, converged

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixel coordinates of world points.

        Parameters
        ----------
        points : (n, 3) float array, world frame

        Returns
        -------
        (n, 2) float64
            ``(u, v)`` 0-based pixel coordinates (column, row); NaN for points
            with ``Z_c <= 0`` (behind the camera).
        """
        pc = self.to_camera(points)
        z = pc[:, 2:3]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = np.where(z > 0, pc[:, :2] / z, np.nan)
        return self.principal_px + self.focal_px * self.distort(xy)

    def pixel_rays(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World-frame directions of the rays through pixels.

        Parameters
        ----------
        uv : (n, 2) float array, 0-based pixel coordinates

        Returns
        -------
        directions : (n, 3) float64
            Unit directions from :attr:`centre`.
        ok : (n,) bool
            False where the distortion could not be inverted.
        """
        xy_d = (np.asarray(uv, np.float64) - self.principal_px) / self.focal_px
        xy, ok = self.undistort(xy_d)
        d_cam = np.concatenate([np.nan_to_num(xy), np.ones((len(xy), 1))], axis=1)
        d = d_cam @ self.rotation
        return d / np.linalg.norm(d, axis=1, keepdims=True), ok

    def scaled(self, factor: float) -> LightstageCamera:
        """Return the same camera for an image resampled by ``1/factor`` (pixel centres kept).

        A pixel of the reduced image covers ``factor x factor`` pixels of the
        original: ``u' = (u + 0.5) / factor - 0.5``.
        """
        h, w = self.image_size
        pp = (self.principal_px + 0.5) / factor - 0.5
        size = (max(1, int(np.ceil(h / factor))), max(1, int(np.ceil(w / factor))))
        return replace(self, focal_px=self.focal_px / factor, principal_px=pp, image_size=size)


@dataclass(frozen=True)
class StitchSettings:
    """Sampling and stitching parameters stored beside the cameras (paper defaults)."""

    boundary_distance_px: float = 100.0
    lam: float = 0.1
    reference_view: int = 0


@dataclass(frozen=True)
class LightstageRig:
    """The cameras of a set of views and how to stitch them.

    Attributes
    ----------
    cameras : tuple of LightstageCamera, one per view
    images : tuple of str
        Image file names as given in the file (may be empty strings).
    settings : StitchSettings
    """

    cameras: tuple[LightstageCamera, ...]
    images: tuple[str, ...]
    settings: StitchSettings


class _Bad(Exception):
    """A malformed field; turned into FormatError / InputError by :func:`rig_from_dict`."""


def _number(block: dict, key: str, where: str, default: float | None = None) -> float:
    if key not in block:
        if default is None:
            raise _Bad(f"{where}: missing '{key}'")
        return default
    value = block[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise _Bad(f"{where}: '{key}' must be a finite number, got {value!r}")
    return float(value)


def _camera(intr: dict, view: dict, where: str) -> LightstageCamera:
    h, w = int(_number(intr, "h", where)), int(_number(intr, "w", where))
    f = _number(intr, "f", where)
    if h < 1 or w < 1 or f <= 0:
        raise _Bad(f"{where}: image size and focal length must be positive")
    origin = _number(intr, "pixel_origin", where, 1.0)
    if origin not in (0.0, 1.0):
        raise _Bad(f"{where}: 'pixel_origin' must be 0 or 1, got {origin}")
    k1, k2, k3, p1, p2 = (_number(intr, k, where, 0.0) for k in _DISTORTION)
    tangential = intr.get("tangential", "matlabrenderer")
    if tangential == "matlabrenderer":
        p1, p2 = p2, p1
    elif tangential != "opencv":
        raise _Bad(f"{where}: 'tangential' must be 'matlabrenderer' or 'opencv'")
    if "T" not in view:
        raise _Bad(f"{where}: missing 'T'")
    try:
        T = np.asarray(view["T"], np.float64)
    except (TypeError, ValueError):
        raise _Bad(f"{where}: 'T' must be a 3x4 or 4x4 matrix of numbers") from None
    if T.shape not in ((3, 4), (4, 4)) or not np.isfinite(T).all():
        raise _Bad(f"{where}: 'T' must be a finite 3x4 or 4x4 matrix, got shape {T.shape}")
    if T.shape == (4, 4) and not np.allclose(T[3], [0, 0, 0, 1]):
        raise _Bad(f"{where}: last row of 'T' must be 0 0 0 1")
    R = T[:3, :3]
    # published extrinsics are rounded to 4 decimals: allow that much non-orthogonality
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-2 or np.linalg.det(R) <= 0:
        raise _Bad(f"{where}: the rotation part of 'T' is not a proper rotation")
    return LightstageCamera(
        rotation=R.copy(), translation=T[:3, 3].copy(), focal_px=f,
        principal_px=np.array([_number(intr, "cx", where), _number(intr, "cy", where)]) - origin,
        image_size=(h, w), distortion=np.array([k1, k2, k3, p1, p2]),
    )


def _rig(data: Any) -> LightstageRig:
    if not isinstance(data, dict) or not isinstance(data.get("views"), list) or not data["views"]:
        raise _Bad("needs a non-empty 'views' list")
    shared = data.get("intrinsics", {})
    if not isinstance(shared, dict):
        raise _Bad("'intrinsics' must be an object")
    cameras, images = [], []
    for i, view in enumerate(data["views"]):
        if not isinstance(view, dict) or not isinstance(view.get("intrinsics", {}), dict):
            raise _Bad(f"views[{i}] must be an object (with an optional 'intrinsics' object)")
        cameras.append(_camera({**shared, **view.get("intrinsics", {})}, view, f"views[{i}]"))
        images.append(str(view.get("image", "")))
    st = data.get("stitching", {})
    if not isinstance(st, dict):
        raise _Bad("'stitching' must be an object")
    d = StitchSettings()
    settings = StitchSettings(
        boundary_distance_px=_number(st, "boundary_distance_px", "stitching",
                                     d.boundary_distance_px),
        lam=_number(st, "lambda", "stitching", d.lam),
        reference_view=int(_number(st, "reference_view", "stitching", d.reference_view)),
    )
    if not 0 <= settings.reference_view < len(cameras):
        raise _Bad(f"stitching: reference_view {settings.reference_view} is not one of the "
                   f"{len(cameras)} views")
    if settings.lam <= 0 or settings.boundary_distance_px < 0:
        raise _Bad("stitching: 'lambda' must be > 0 and 'boundary_distance_px' >= 0")
    return LightstageRig(tuple(cameras), tuple(images), settings)


def rig_from_dict(data: Any, source: str | os.PathLike | None = None) -> LightstageRig:
    """Build a :class:`LightstageRig` from the parsed JSON of a camera file (see module notes).

    Parameters
    ----------
    data : dict
    source : path-like, optional
        The file the data came from, named in error messages.

    Raises
    ------
    FormatError
        (with ``source``) or InputError (without): missing or malformed fields.
    """
    try:
        return _rig(data)
    except _Bad as exc:
        if source is None:
            raise InputError(f"camera description: {exc}") from None
        raise FormatError(source, str(exc)) from None


def load_cameras(path: str | os.PathLike) -> LightstageRig:
    """Read a lightstage camera file (JSON, format in the module notes).

    Raises
    ------
    InputError
        The file does not exist.
    FormatError
        Not JSON, or malformed fields; the message names the file.
    """
    p = Path(path)
    return rig_from_dict(read_json_file(p), p)
