"""Target landmarks: model landmark positions at a state, projection, visibility, likelihood.

Only landmarks that the target marks visible and that resolve to a model
vertex take part (others are listed in :attr:`LandmarkTarget.unknown`).

Visibility of a model landmark is decided by ray casting from the camera to
the landmark on the model's **mean shape** placed with the state's pose and
camera (a second, fixed Embree scene). It is then a function of the
parameters alone (not of what the renderer happens to hold), so the landmark
factor is a proper density and the landmark filter an exact MH step, and it
needs no ray cast of the proposed geometry before the filter. It differs from
the instance's own occlusion only where a shape change moves a landmark
across an occluding contour.

A hidden landmark (occluded, behind the camera, or not projectable) that the
target marks visible scores ``log(eps) - log(W H)`` instead of the Gaussian:
an annotation error (probability ``eps``, default 0.05, of marking a hidden
point visible) placed uniformly over the image. The factor is then a
likelihood of the click *and* its visibility flag for every state, and it
neither rewards hiding landmarks (dropping them would: every Gaussian term is
a negative log density) nor leaves a plateau of "everything hidden" states
(the face turned away) nearly as likely as a mediocre fit. See
:func:`mcmcfit.targets.likelihoods.landmark_log_lik`. Landmarks projecting outside the
image keep the Gaussian term.

This module imports :mod:`albedo_model` (camera, errors, model, params,
render.raycast), :mod:`pipeline.synthetic.head.landmarks` (the LFW landmark names) and
:mod:`mcmcfit.targets.likelihoods`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np

from albedo_model.camera import eye_position_model, project, towards_camera_model
from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from albedo_model.params import ImageSize, RenderParameter
from albedo_model.render.raycast import RayCaster, visible_points
from pipeline.synthetic.head.landmarks import LFW_TLMS_NAMES
from mcmcfit.targets.likelihoods import FACE_BOX_LANDMARKS, LOG_2PI, landmark_log_lik

__all__ = ["FACE_BOX_ENLARGEMENT", "FACE_BOX_RAISE", "FACE_EXTENT_LANDMARKS", "MIN_LANDMARKS",
           "FaceBoxTarget", "LandmarkGeometry", "LandmarkTarget", "face_box_names", "face_box_of",
           "target_landmarks"]


#: Fewest target landmarks known to the model that a fit accepts (a similarity
#: pose guess needs two; a third constrains the rotation).
MIN_LANDMARKS = 3


def target_landmarks(landmarks) -> dict[str, np.ndarray]:
    """Visible 2-D target landmarks as ``{name: (2,) float64 pixels}``.

    Accepts a list of :class:`~albedo_model.io.tlms.Landmark` (occluded ones are
    dropped; 3-D ones are rejected) or a mapping ``name -> (x, y)``.
    """
    out: dict[str, np.ndarray] = {}
    if isinstance(landmarks, Mapping):
        items: Iterable = ((str(k), v, True) for k, v in landmarks.items())
    else:
        items = ((lm.name, lm.point, lm.visible) for lm in landmarks)
    for name, point, visible in items:
        if not visible:
            continue
        p = np.asarray(point, np.float64).reshape(-1)
        if p.shape != (2,) or not np.all(np.isfinite(p)):
            raise InputError(f"landmark {name!r} must be a finite 2-D pixel position, got {point!r}")
        if name in out:
            raise InputError(f"landmark {name!r} occurs twice")
        out[name] = p
    return out


class LandmarkGeometry:
    """Model landmark points at a state's shape, and their visibility from the camera.

    Parameters
    ----------
    model : MorphableModel
    threads : int
        Ray-casting threads of the visibility scene.
    """

    def __init__(self, model: MorphableModel, *, threads: int = 1):
        self.model = model
        self._vertex = dict(model.landmark_vertices)
        self._rows: dict[tuple[str, ...], tuple] = {}
        mean = model.shape_instance()
        self._mean_points = {n: mean[i] for n, i in self._vertex.items()}
        self._caster = RayCaster(np.ascontiguousarray(mean, np.float32), model.triangles,
                                 threads=threads, update="rebuild")

    @property
    def names(self) -> list[str]:
        """Model landmarks that sit on a vertex."""
        return list(self._vertex)

    def _stacked(self, names: tuple[str, ...]):
        """Mean (k, 3) and scaled bases (k, 3, ks), (k, 3, ke) of the landmark vertices."""
        if names not in self._rows:
            rows = np.concatenate([np.arange(3 * self._vertex[n], 3 * self._vertex[n] + 3)
                                   for n in names]) if names else np.zeros(0, int)
            s, e = self.model.shape, self.model.expression
            mean = s.mean[rows].astype(np.float64)
            eb = None
            if e is not None:
                mean = mean + e.mean[rows]
                eb = e.scaled_basis[rows].astype(np.float64)
            self._rows[names] = (mean, s.scaled_basis[rows].astype(np.float64), eb)
        return self._rows[names]

    def points(self, names: list[str], params: RenderParameter) -> np.ndarray:
        """Model-frame positions (k, 3) float64 (mm) at the shape and expression of ``params``."""
        mean, sb, eb = self._stacked(tuple(names))
        a = np.asarray(params.momo.shape, np.float64)
        b = np.asarray(params.momo.expression, np.float64)
        p = mean + sb[:, : a.shape[0]] @ a
        if eb is not None and b.shape[0]:
            p = p + eb[:, : b.shape[0]] @ b
        return p.reshape(-1, 3)

    def point(self, name: str, params: RenderParameter) -> np.ndarray:
        """One landmark's model-frame position (3,): the proposals' ``landmark_point``."""
        if name not in self._vertex:
            raise InputError(f"the model has no landmark {name!r} on a vertex")
        return self.points([name], params)[0]

    def visible(self, names: list[str], params: RenderParameter) -> np.ndarray:
        """(k,) bool: the mean-shape landmark has a free line of sight to the camera.

        Occluders within :data:`VISIBILITY_SHELL` (a fraction of the model's
        bounding-box diagonal, ~10 mm on a head) in front of a landmark do not
        hide it: mouth and eye corners sit in creases that the mean shape's lips
        and lids overhang, and a frontal face whose lip corner is "hidden" by a
        lip bulge 2-8 mm in front of it made poses 10-15 deg off the likelier
        ones (one of five synthetic faces).
        """
        pts = np.array([self._mean_points[n] for n in names]).reshape(-1, 3)
        p = params
        eps = VISIBILITY_SHELL * self._caster.scale
        with np.errstate(all="ignore"):
            if p.camera.orthographic:
                return visible_points(pts, None, self._caster, eps,
                                      direction=towards_camera_model(p.pose, p.view))
            return visible_points(pts, eye_position_model(p.pose, p.view), self._caster, eps)


#: Depth of the shell in front of a landmark in which the surface does not hide it, as a
#: fraction of the model's bounding-box diagonal (0.04: ~10 mm on a head model).
VISIBILITY_SHELL = 0.04


class LandmarkTarget:
    """The landmark likelihood of a set of clicked 2-D landmarks.

    Parameters
    ----------
    geometry : LandmarkGeometry
    landmarks : list of Landmark or mapping name -> (x, y)
        Target pixels (x right, y down); occluded (visible=False) ones are ignored.
    sigma : float
        Landmark noise in pixels (4 in the reference).
    image_size : ImageSize
        Sets the hidden-landmark density ``log(hidden_probability) - log(W H)``.
    hidden_probability : float in (0, 1]
        Probability that a landmark hidden in the model is nevertheless clicked
        as visible (an annotation or model error).
    sigma_factors : mapping name -> float, optional
        Per-landmark factors of ``sigma`` (names not in it: 1), e.g. the
        reliability of detected points.

    Raises
    ------
    InputError
        Fewer than :data:`MIN_LANDMARKS` target landmarks are model landmarks.
    """

    def __init__(self, geometry: LandmarkGeometry, landmarks, *, sigma: float = 4.0,
                 image_size: ImageSize, hidden_probability: float = 0.05,
                 sigma_factors=None):
        if not (math.isfinite(sigma) and sigma > 0):
            raise InputError(f"landmark sigma must be > 0, got {sigma!r}")
        if not 0.0 < hidden_probability <= 1.0:
            raise InputError(f"hidden-landmark probability must be in (0, 1], "
                             f"got {hidden_probability!r}")
        given = target_landmarks(landmarks)
        known = set(geometry.names)
        self.geometry = geometry
        self.names = [n for n in given if n in known]
        self.unknown = [n for n in given if n not in known]
        if len(self.names) < MIN_LANDMARKS:
            count = "none" if not self.names else f"only {len(self.names)}"
            raise InputError(
                f"{count} of the {len(given)} visible target landmarks is a landmark of the "
                f"model; a fit needs at least {MIN_LANDMARKS}"
                + (f" (unknown: {', '.join(self.unknown[:5])})" if self.unknown else ""))
        self.observed = np.array([given[n] for n in self.names])
        self.sigma = float(sigma)
        if sigma_factors:
            factors = np.array([float(sigma_factors.get(n, 1.0)) for n in self.names])
            if not np.all(np.isfinite(factors) & (factors > 0)):
                raise InputError("landmark sigma factors must be finite and > 0")
            self.sigma = self.sigma * factors  # (k,) per landmark
        self.hidden_log_density = (math.log(hidden_probability)
                                   - math.log(float(image_size.width) * float(image_size.height)))

    def project(self, params: RenderParameter) -> tuple[np.ndarray, np.ndarray]:
        """Projected model landmarks (k, 2) pixels and their visibility (k,) bool."""
        pts = self.geometry.points(self.names, params)
        px, depth = project(pts, params.pose, params.view, params.camera, params.image_size)
        ok = np.all(np.isfinite(px), axis=1) & (depth > 0.0) & (depth < 1.0)
        if ok.any():
            ok &= self.geometry.visible(self.names, params)
        return px, ok

    def log_lik(self, params: RenderParameter) -> float:
        """Landmark log likelihood of ``params`` (see the module notes)."""
        return self.log_lik_of(*self.project(params))

    def log_lik_of(self, px: np.ndarray, visible: np.ndarray) -> float:
        """Landmark log likelihood of projected landmarks ``px`` (k, 2) and their visibility (k,).

        ``px`` and ``visible`` as :meth:`project` returns them.
        """
        return landmark_log_lik(np.where(visible[:, None], px, 0.0), self.observed, visible,
                                self.sigma, self.hidden_log_density)


#: Face landmarks whose extent a face box measures: LFW's 16 ``.tlms`` points (brows,
#: eyes, nose, mouth, chin). A model uses those it has.
FACE_EXTENT_LANDMARKS = LFW_TLMS_NAMES

#: A face box is the bounding box of the face landmarks, enlarged by this factor ...
FACE_BOX_ENLARGEMENT = 1.5
#: ... about a centre this fraction of the landmarks' height above theirs. Measured on the
#: AlbedoMM fitter's fit of a 250x250 LFW image (its parameters placing a real mean head):
#: LFW's detector box, the central 113.6 px square, is 1.52 times the geometric-mean side
#: of the 16 landmarks' box (66.5 x 84 px, lower brows to chin) and its centre 20 px
#: (0.24 of their height) higher: the detector's box reaches from the hairline to the chin.
FACE_BOX_RAISE = 0.25


def face_box_of(points: np.ndarray) -> np.ndarray:
    """Return the face box ``(x0, y0, x1, y1)`` that a detector reports for face landmarks.

    Parameters
    ----------
    points : (k, 2) float
        Pixel positions (x right, y down) of face landmarks
        (:data:`FACE_EXTENT_LANDMARKS`, or those of them a model has).

    Returns
    -------
    (4,) float64
        Their bounding box enlarged :data:`FACE_BOX_ENLARGEMENT` times about a centre
        raised by :data:`FACE_BOX_RAISE` of its height (the convention of
        :class:`FaceBoxTarget`).
    """
    p = np.asarray(points, np.float64).reshape(-1, 2)
    lo, hi = p.min(axis=0), p.max(axis=0)
    half = 0.5 * FACE_BOX_ENLARGEMENT * (hi - lo)
    cx, cy = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]) - FACE_BOX_RAISE * (hi[1] - lo[1])
    return np.array([cx - half[0], cy - half[1], cx + half[0], cy + half[1]])


def face_box_names(geometry: LandmarkGeometry) -> list[str]:
    """Return the model's landmarks whose extent a face box measures (see :class:`FaceBoxTarget`).

    Raises
    ------
    InputError
        The model lacks one of the eye, mouth and nose landmarks
        (:data:`~mcmcfit.targets.likelihoods.FACE_BOX_LANDMARKS`).
    """
    missing = [n for n in FACE_BOX_LANDMARKS if n not in geometry.names]
    if missing:
        raise InputError(f"a face box needs model landmark {missing[0]!r}")
    return [n for n in FACE_EXTENT_LANDMARKS if n in geometry.names] + [
        n for n in FACE_BOX_LANDMARKS if n not in FACE_EXTENT_LANDMARKS]


def _box(box) -> np.ndarray:
    b = np.asarray(box, np.float64).reshape(-1)
    if b.shape != (4,) or not np.all(np.isfinite(b)) or not (b[2] > b[0] and b[3] > b[1]):
        raise InputError(f"face box must be (x0, y0, x1, y1) with x1 > x0, y1 > y0: {box!r}")
    return b


class FaceBoxTarget:
    """Face-box likelihood: a detector's box (x0, y0, x1, y1) in pixels instead of landmarks.

    The box is read as :func:`face_box_of` the model's face landmarks
    (:func:`face_box_names`) projected with the state: with ``B`` that predicted
    box, ``s`` the ratio of the geometric-mean sides of ``B`` and the box and ``c``
    the offset of their centres, the log likelihood is
    ``log N(log s; 0, scale_log_sigma) + log N(c / diag; 0, centre_sigma^2 I_2)``
    (``diag`` the box's diagonal; a density over ``(log s, c / diag)``, like
    scalismo's face box, whose measures - eye and mouth spans, nose tip - put a
    face on LFW's box about 20 % too large and 0.1 diagonal too high).

    Parameters
    ----------
    geometry : LandmarkGeometry
    box : (x0, y0, x1, y1) pixels
    scale_log_sigma : float
        Standard deviation of ``log s``.
    centre_sigma : float
        Standard deviation of each component of ``c``, in units of the box diagonal.
    yaw_sigma_deg, pitch_sigma_deg : float or None
        A detector's box is evidence of a roughly frontal face (face detectors find
        faces within about +-45 deg of yaw and less pitch): a zero-mean Gaussian
        factor on the head's yaw and pitch (None: none). A box alone says nothing
        of the head's orientation otherwise, and without this the image stage can
        settle in a steeply pitched mode (measured on ``skimage.data.astronaut()``:
        pitch 34 deg against 10 deg with landmarks).
    """

    def __init__(self, geometry: LandmarkGeometry, box, *, scale_log_sigma: float = 0.1,
                 centre_sigma: float = 0.1, yaw_sigma_deg: float | None = 30.0,
                 pitch_sigma_deg: float | None = 10.0):
        self.names = face_box_names(geometry)
        self.geometry, self.box = geometry, _box(box)
        self.scale_log_sigma, self.centre_sigma = float(scale_log_sigma), float(centre_sigma)
        b = self.box
        self._size = math.sqrt((b[2] - b[0]) * (b[3] - b[1]))
        self._centre = 0.5 * (b[:2] + b[2:])
        self._diag = math.hypot(b[2] - b[0], b[3] - b[1])
        self._const = (-1.5 * LOG_2PI - math.log(self.scale_log_sigma)
                       - 2.0 * math.log(self.centre_sigma))
        self._orientation = tuple(
            (attr, math.radians(sd)) for attr, sd in (("yaw", yaw_sigma_deg),
                                                      ("pitch", pitch_sigma_deg)) if sd)
        self._const -= sum(0.5 * LOG_2PI + math.log(sd) for _, sd in self._orientation)

    def log_lik(self, params: RenderParameter) -> float:
        """Return the face-box log likelihood of ``params`` (-inf: a landmark behind the eye)."""
        pts = self.geometry.points(self.names, params)
        px, depth = project(pts, params.pose, params.view, params.camera, params.image_size)
        if not (np.all(np.isfinite(px)) and np.all(depth > 0)):
            return -math.inf
        pred = face_box_of(px)
        size = math.sqrt((pred[2] - pred[0]) * (pred[3] - pred[1]))
        if not size > 0.0:
            return -math.inf
        log_s = math.log(size / self._size) / self.scale_log_sigma
        c = (0.5 * (pred[:2] + pred[2:]) - self._centre) / (self._diag * self.centre_sigma)
        turn = sum((getattr(params.pose, attr) / sd) ** 2 for attr, sd in self._orientation)
        return float(self._const - 0.5 * (log_s * log_s + float(c @ c) + turn))
