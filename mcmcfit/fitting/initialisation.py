"""Starting parameters of a fit: input checks, the default camera for the image size, a pose guess.

:func:`check_fit_inputs` refuses, in microseconds and before anything is set up,
inputs that are not a face photograph a fit can use: an image too small, target
landmarks far outside the image, a face of a few pixels.

The guess places the mean face so that its landmarks fit the target's in a
least-squares sense: first a frontal similarity (scale and image offset,
linear), which sets the distance from the focal length and the translation;
then optionally a perspective least-squares refinement of the three angles
and the translation (``scipy.optimize.least_squares`` with a soft-L1 loss),
kept only if it lowers the reprojection error. A face box alone places the
face (not the head) frontally so that its landmarks give the box by the
detector's convention (:func:`mcmcfit.targets.landmarks.face_box_of`).

This module imports :mod:`albedo_model` (camera, errors, model, params) and
:mod:`mcmcfit.targets.landmarks` (and :mod:`scipy.optimize` inside a function).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from albedo_model.camera import pixel_scale, principal_point_px, project
from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import MoMoCoefficients, RenderParameter, default_square, fit_to_image_size
from mcmcfit.targets.landmarks import (
    FACE_BOX_ENLARGEMENT,
    FACE_BOX_RAISE,
    MIN_LANDMARKS,
    LandmarkGeometry,
    face_box_names,
    face_box_of,
    target_landmarks,
)

__all__ = ["MIN_FACE_PX", "MIN_IMAGE_PX", "OUTSIDE_MARGIN", "check_fit_inputs", "initial_params",
           "pose_from_face_box", "pose_from_landmarks"]

#: Smallest image side a fit accepts. The default camera frames a head at 1 m in about
#: 75 % of the image, so a 32 px image holds about the smallest face that is still
#: worth fitting (the 24 px wide head of the hard cases, landmarks ~13 x 16 px) with a
#: few pixels of background around it for the colour-histogram background model.
#: Below that the face is a handful of pixels, and a 1 x 1 image would still run the
#: whole schedule (minutes) to fit nothing.
MIN_IMAGE_PX = 32
#: Smallest face: the larger side of the bounding box of the target landmarks used.
#: At 8 px the eyes are ~4 px apart and eyes, nose and mouth a pixel or two each: the
#: landmark and image likelihoods no longer constrain shape or albedo. The 24 px wide
#: face of the hard cases spans ~16 px. A face box must be as large as the box of such
#: landmarks (``FACE_BOX_ENLARGEMENT x 8 px`` = 12 px per side).
MIN_FACE_PX = 8.0
#: Target landmarks may lie this far outside the image (a fraction of its smaller side,
#: e.g. a chin just below the frame); farther out they are an error.
OUTSIDE_MARGIN = 0.1


def check_fit_inputs(width: int, height: int, *, landmarks=None, face_box=None,
                     model_landmarks: Iterable[str] = ()) -> None:
    """Raise InputError when the inputs of a fit cannot be a face photograph to fit.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    landmarks : list of Landmark or mapping name -> (x, y), optional
        Target landmarks; only the visible ones the model has are checked (with
        fewer than :data:`~mcmcfit.targets.landmarks.MIN_LANDMARKS` of them the
        landmark target raises its own error later).
    face_box : (x0, y0, x1, y1), optional
        Checked only without landmarks (the fit ignores it otherwise).
    model_landmarks : iterable of str
        The model's landmark names.

    Raises
    ------
    InputError
        An image smaller than :data:`MIN_IMAGE_PX` per side; a used landmark more
        than :data:`OUTSIDE_MARGIN` of the image outside it (named), or none inside
        it; landmarks or a face box smaller than :data:`MIN_FACE_PX`; a face box
        mostly outside the image.
    """
    w, h = int(width), int(height)
    if min(w, h) < MIN_IMAGE_PX:
        raise InputError(f"the image is {w}x{h} pixels; a face fit needs at least "
                         f"{MIN_IMAGE_PX}x{MIN_IMAGE_PX}")
    if landmarks is not None:
        known = set(model_landmarks)
        used = {n: p for n, p in target_landmarks(landmarks).items() if n in known}
        if len(used) >= MIN_LANDMARKS:
            _check_landmarks(used, w, h)
    elif face_box is not None:
        _check_face_box(_face_box(face_box), w, h)


def _check_landmarks(used: dict[str, np.ndarray], w: int, h: int) -> None:
    pts = np.array(list(used.values()))
    margin = OUTSIDE_MARGIN * min(w, h)
    far = [n for n, (x, y) in used.items()
           if x < -margin or y < -margin or x > w + margin or y > h + margin]
    if far:
        shown = ", ".join(f"{n} ({used[n][0]:.0f}, {used[n][1]:.0f})" for n in far[:4])
        more = f" and {len(far) - 4} more" if len(far) > 4 else ""
        raise InputError(f"{len(far)} of {len(used)} target landmarks lie more than "
                         f"{margin:.0f} px outside the {w}x{h} image: {shown}{more} "
                         "(landmarks of another image or image size?)")
    inside = (pts[:, 0] >= 0) & (pts[:, 0] <= w) & (pts[:, 1] >= 0) & (pts[:, 1] <= h)
    if not inside.any():
        raise InputError(f"none of the {len(used)} target landmarks lies inside the {w}x{h} image")
    extent = float(np.ptp(pts, axis=0).max())
    if extent < MIN_FACE_PX:
        raise InputError(f"the target landmarks span only {extent:.1f} px: a face smaller than "
                         f"{MIN_FACE_PX:.0f} px cannot be fitted")


def _check_face_box(b: np.ndarray, w: int, h: int) -> None:
    side = float(min(b[2] - b[0], b[3] - b[1]))
    box = f"face box ({b[0]:.0f}, {b[1]:.0f}, {b[2]:.0f}, {b[3]:.0f})"
    if side < FACE_BOX_ENLARGEMENT * MIN_FACE_PX:
        raise InputError(f"{box} is only {side:.1f} px across: a face box smaller than "
                         f"{FACE_BOX_ENLARGEMENT * MIN_FACE_PX:.0f} px cannot be fitted")
    inside_w = max(0.0, min(b[2], w) - max(b[0], 0.0))
    inside_h = max(0.0, min(b[3], h) - max(b[1], 0.0))
    if inside_w * inside_h < 0.5 * (b[2] - b[0]) * (b[3] - b[1]):
        raise InputError(f"{box} lies mostly outside the {w}x{h} image")


def _face_box(box) -> np.ndarray:
    b = np.asarray(box, np.float64).reshape(-1)
    if b.shape != (4,) or not np.all(np.isfinite(b)) or not (b[2] > b[0] and b[3] > b[1]):
        raise InputError(f"face box must be (x0, y0, x1, y1) with x1 > x0, y1 > y0: {box!r}")
    return b


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
    """Frontal pose whose face landmarks give the face box ``(x0, y0, x1, y1)``.

    The box is read as :class:`~mcmcfit.targets.landmarks.FaceBoxTarget` reads it:
    the bounding box of the model's face landmarks (brows, eyes, nose, mouth, chin;
    not the head with its scalp and ears), enlarged and raised by the detector's
    convention (:func:`~mcmcfit.targets.landmarks.face_box_of`). A frontal similarity
    sets the distance from the box size and the translation from its centre; two
    perspective corrections then make the projected box match (the face-box
    likelihood is at its maximum there).

    Parameters
    ----------
    geometry : LandmarkGeometry
    box : (x0, y0, x1, y1) pixels
    params : RenderParameter
        Camera, image size and coefficients to keep (the pose is replaced).

    Raises
    ------
    InputError
        A malformed box, or a model without eye, mouth and nose landmarks.
    """
    b = _face_box(box)
    names = face_box_names(geometry)
    pts = geometry.points(names, params)
    lo, hi = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
    w_mm, h_mm = hi - lo
    size_px = np.sqrt((b[2] - b[0]) * (b[3] - b[1]))
    scale = float(size_px / (FACE_BOX_ENLARGEMENT * np.sqrt(w_mm * h_mm)))
    # the box centre in the model frame (y up): the landmarks' centre raised
    cx_mm = 0.5 * (lo[0] + hi[0])
    cy_mm = 0.5 * (lo[1] + hi[1]) + FACE_BOX_RAISE * h_mm
    bx, by = 0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])
    ox, oy = float(bx - scale * cx_mm), float(by + scale * cy_mm)
    z_mean = float(pts[:, 2].mean())
    start = _with_similarity(params, scale, ox, oy, z_mean)
    for _ in range(2):
        px, depth = project(pts, start.pose, start.view, start.camera, start.image_size)
        if not (np.all(np.isfinite(px)) and np.all(depth > 0)):
            break
        pred = face_box_of(px)
        ratio = float(size_px / np.sqrt((pred[2] - pred[0]) * (pred[3] - pred[1])))
        # u = o + s x: scaling by r maps the predicted centre p to o + r (p - o)
        scale *= ratio
        ox = float(bx + ratio * (ox - 0.5 * (pred[0] + pred[2])))
        oy = float(by + ratio * (oy - 0.5 * (pred[1] + pred[3])))
        start = _with_similarity(params, scale, ox, oy, z_mean)
    return start
