"""Starting parameters of a fit: the default camera for the image size and a pose guess.

The guess places the mean face so that its landmarks fit the target's in a
least-squares sense: first a frontal similarity (scale and image offset,
linear), which sets the distance from the focal length and the translation;
then optionally a perspective least-squares refinement of the three angles
and the translation (``scipy.optimize.least_squares`` with a soft-L1 loss),
kept only if it lowers the reprojection error. A face box alone gives the
distance from its size and the translation from its centre (frontal).

This module imports :mod:`albedo_model` (camera, errors, model, params),
:mod:`mcmcfit.targets.landmarks` and :mod:`mcmcfit.targets.likelihoods`.
"""

from __future__ import annotations

import numpy as np

from albedo_model.camera import pixel_scale, principal_point_px, project
from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import MoMoCoefficients, RenderParameter, default_square, fit_to_image_size
from mcmcfit.targets.landmarks import LandmarkGeometry
from mcmcfit.targets.likelihoods import FACE_BOX_LANDMARKS

__all__ = ["initial_params", "pose_from_face_box", "pose_from_landmarks"]


def initial_params(model: MorphableModel, width: int, height: int, *, n_shape: int = 50,
                   n_albedo: int = 50, n_expression: int = 5, model_uri: str = "") -> RenderParameter:
    """``fit_to_image_size(default_square(), W, H)`` with zero coefficients.

    The coefficient counts are clipped to the model's ranks (the reference
    uses 50 shape / 50 colour / 5 expression).
    """
    ranks = model.ranks
    momo = MoMoCoefficients.zeros(min(n_shape, ranks["shape"]), min(n_albedo, ranks["diffuse"]),
                                  min(n_expression, ranks.get("expression", 0)), model_uri)
    return fit_to_image_size(default_square(), int(width), int(height))._replace(momo=momo)


def _with_similarity(params: RenderParameter, scale: float, offset_x: float,
                     offset_y: float, z_mean: float) -> RenderParameter:
    """Frontal pose with ``u = a + s x``, ``v = b - s y`` for points at depth ``z_mean``."""
    fx, _ = pixel_scale(params.camera, params.image_size)
    cx, cy = principal_point_px(params.camera, params.image_size)
    depth = fx / scale
    vz = params.view.translation[2]
    tz = vz - depth - z_mean
    pose = params.pose._replace(yaw=0.0, pitch=0.0, roll=0.0,
                                translation=((offset_x - cx) / scale, (cy - offset_y) / scale, tz))
    return params._replace(pose=pose)


def pose_from_landmarks(geometry: LandmarkGeometry, names: list[str], observed: np.ndarray,
                        params: RenderParameter, *, refine: bool = True) -> RenderParameter:
    """Pose guess from 2-D landmarks (see the module notes).

    Parameters
    ----------
    geometry : LandmarkGeometry
    names : list of str, model landmarks
    observed : (k, 2) float, their target pixels
    params : RenderParameter
        Camera, image size and coefficients to keep (the pose is replaced).
    refine : bool
        Run the perspective least-squares refinement (needs >= 4 landmarks).

    Raises
    ------
    InputError
        Fewer than 2 landmarks, or a degenerate (zero or negative) scale.
    """
    obs = np.asarray(observed, np.float64).reshape(-1, 2)
    if len(names) < 2:
        raise InputError("a pose guess needs at least 2 landmarks")
    pts = geometry.points(names, params)
    k = len(names)
    a = np.zeros((2 * k, 3))
    a[:k, 0], a[:k, 1] = pts[:, 0], 1.0
    a[k:, 0], a[k:, 2] = -pts[:, 1], 1.0
    rhs = np.concatenate([obs[:, 0], obs[:, 1]])
    (scale, ox, oy), *_ = np.linalg.lstsq(a, rhs, rcond=None)
    if not (np.isfinite(scale) and scale > 0):
        raise InputError("landmarks give a degenerate face size (are left and right swapped?)")
    start = _with_similarity(params, float(scale), float(ox), float(oy), float(pts[:, 2].mean()))
    if not refine or k < 4:
        return start
    return _refine(start, pts, obs)


def _residuals(x: np.ndarray, params: RenderParameter, pts: np.ndarray,
               obs: np.ndarray) -> np.ndarray:
    pose = params.pose._replace(yaw=x[0], pitch=x[1], roll=x[2], translation=tuple(x[3:6]))
    px, _ = project(pts, pose, params.view, params.camera, params.image_size)
    r = (px - obs).reshape(-1)
    return np.where(np.isfinite(r), r, 1e6)


def _refine(start: RenderParameter, pts: np.ndarray, obs: np.ndarray) -> RenderParameter:
    from scipy.optimize import least_squares

    x0 = np.array([start.pose.yaw, start.pose.pitch, start.pose.roll, *start.pose.translation])
    cost0 = float(np.sum(_residuals(x0, start, pts, obs) ** 2))
    try:
        sol = least_squares(_residuals, x0, args=(start, pts, obs), loss="soft_l1", f_scale=4.0,
                            x_scale=np.array([0.1, 0.1, 0.1, 10.0, 10.0, 50.0]), max_nfev=200)
    except ValueError:
        return start
    x = sol.x
    cost = float(np.sum(_residuals(x, start, pts, obs) ** 2))
    depth_ok = start.view.translation[2] - x[5] > 1.0
    if not (np.all(np.isfinite(x)) and cost < cost0 and depth_ok and np.all(np.abs(x[:3]) < 1.6)):
        return start
    pose = start.pose._replace(yaw=float(x[0]), pitch=float(x[1]), roll=float(x[2]),
                               translation=(float(x[3]), float(x[4]), float(x[5])))
    return start._replace(pose=pose)


def pose_from_face_box(geometry: LandmarkGeometry, box, params: RenderParameter) -> RenderParameter:
    """Frontal pose fitting a face box ``(x0, y0, x1, y1)`` (the measures of the face-box likelihood).

    The larger of the eye-to-eye and eyes-to-lips spans is set to diag / 3 and
    the nose tip to the box centre.
    """
    b = np.asarray(box, np.float64).reshape(-1)
    if b.shape != (4,) or not (b[2] > b[0] and b[3] > b[1]):
        raise InputError(f"face box must be (x0, y0, x1, y1) with x1 > x0, y1 > y0: {box!r}")
    names = list(FACE_BOX_LANDMARKS)
    missing = [n for n in names if n not in geometry.names]
    if missing:
        raise InputError(f"a face-box pose guess needs model landmark {missing[0]!r}")
    p = dict(zip(names, geometry.points(names, params)))
    eye_l = 0.5 * (p["left.eye.corner_outer"] + p["left.eye.corner_inner"])
    eye_r = 0.5 * (p["right.eye.corner_outer"] + p["right.eye.corner_inner"])
    lips = 0.5 * (p["left.lips.corner"] + p["right.lips.corner"])
    span_mm = max(np.linalg.norm(eye_l[:2] - eye_r[:2]),
                  np.linalg.norm(0.5 * (eye_l[:2] + eye_r[:2]) - lips[:2]))
    diag = float(np.hypot(b[2] - b[0], b[3] - b[1]))
    scale = (diag / 3.0) / span_mm
    nose = p["center.nose.tip"]
    cx, cy = 0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])
    return _with_similarity(params, scale, cx - scale * nose[0], cy + scale * nose[1], float(nose[2]))
