"""Pose and camera proposals: rotation, translation, distance, focal scaling, image centring.

Mirrors scalismo-faces' pose proposals (``reference-sampler.md`` §4) with exact
log transition ratios. Angles in radians, translations and distances in mm.

This module imports only :mod:`albedo_model` (camera, errors, params) and
:mod:`proposals.base`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from albedo_model.camera import project_eye, to_eye
from albedo_model.errors import InputError
from albedo_model.params import Block, RenderParameter
from proposals.base import Move, Proposal, ProposalState, check_scale

__all__ = ["Rotation", "Translation", "Distance", "FocalScaling", "ImageCentered", "AXES"]

#: Euler angle names of :class:`~albedo_model.params.Pose` a rotation can move.
AXES = ("yaw", "pitch", "roll")


@dataclass(frozen=True)
class Rotation:
    """Rotation about one Euler axis: ``angle += N(0, sigma)``.

    Parameters
    ----------
    axis : {"yaw", "pitch", "roll"}
    sigma : float, rad
    name : str, optional (default ``"<axis>-<sigma>"``)

    Notes
    -----
    The reference draws ``a ~ N(0, sigma)``, converts the rotation by ``a`` about
    the fixed axis to Euler angles and adds them. A rotation about a coordinate
    axis has the single Euler angle ``a`` on that axis (for |a| < pi/2), so the
    move is an additive increment of one angle, done here exactly (also for
    |a| >= pi/2, no wrapping). It is a symmetric random walk on that angle:
    ``q(x'|x) = phi_sigma(a) = q(x|x')``, ratio 0.
    """

    axis: str
    sigma: float
    name: str = ""
    touches: ClassVar[Block] = Block.POSE

    def __post_init__(self) -> None:
        """Validate the axis and scale and set a default name."""
        if self.axis not in AXES:
            raise InputError(f"rotation axis must be one of {AXES}, got {self.axis!r}")
        check_scale(self.sigma, "rotation sigma")
        if not self.name:
            object.__setattr__(self, "name", f"{self.axis}-{self.sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        a = rng.normal(0.0, self.sigma)
        pose = params.pose._replace(**{self.axis: float(getattr(params.pose, self.axis) + a)})
        return Move(params._replace(pose=pose), 0.0, Block.POSE, self.name)


@dataclass(frozen=True)
class Translation:
    """In-plane translation: ``t_x += N(0, sigma)``, ``t_y += N(0, sigma)`` (mm); ``t_z`` kept.

    Notes
    -----
    Symmetric Gaussian random walk on (t_x, t_y): ratio 0.
    """

    sigma: float
    name: str = ""
    touches: ClassVar[Block] = Block.POSE

    def __post_init__(self) -> None:
        """Validate the scale and set a default name."""
        check_scale(self.sigma, "translation sigma")
        if not self.name:
            object.__setattr__(self, "name", f"translation-{self.sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        dx, dy = rng.normal(0.0, self.sigma, 2)
        tx, ty, tz = params.pose.translation
        pose = params.pose._replace(translation=(float(tx + dx), float(ty + dy), float(tz)))
        return Move(params._replace(pose=pose), 0.0, Block.POSE, self.name)


@dataclass(frozen=True)
class Distance:
    """Move the face along the viewing axis and zoom to keep its image size.

    With ``d = view.t_z - pose.t_z`` (mm in front of the camera), draw
    ``d' = d + N(0, sigma)`` reflected at ``min_distance`` (``d' <- 2 d_min - d'``
    when it falls below), set ``pose.t_z = view.t_z - d'`` and
    ``f' = f d' / d``.

    Parameters
    ----------
    sigma : float, mm
    min_distance : float, mm
        Lower bound of the distance (the reference's ``d > 1``).
    name : str, optional (default ``"distance-<sigma>"``)

    Notes
    -----
    Changes ``pose.translation[2]`` and ``camera.focal_length``: POSE | CAMERA.

    Ratio: in the coordinates ``(d, k = f/d)`` the move is a reflected Gaussian
    walk on ``d`` with ``k`` fixed; the reflected density
    ``phi(d' - d) + phi(d' + d - 2 d_min)`` is symmetric, so the ratio there is 0.
    The stored coordinates are ``(t_z, f) = (view_z - d, k d)`` with
    ``|d(t_z, f) / d(d, k)| = d``; a target density ``p(t_z, f)`` is
    ``p d`` in (d, k), so ``log_q_ratio = log d' - log d`` (= ``log f' - log f``).
    The reference clamps the step to ``min(d - 1, N(0, sigma))``, which piles
    mass onto ``d = 1`` and breaks reversibility; reflection keeps the
    kernel symmetric without ever returning a -inf ratio. The state space is
    ``d > min_distance``; a state outside it raises ``InputError``.
    """

    sigma: float
    min_distance: float = 1.0
    name: str = ""
    touches: ClassVar[Block] = Block.POSE | Block.CAMERA

    def __post_init__(self) -> None:
        """Validate the scales and set a default name."""
        check_scale(self.sigma, "distance sigma")
        check_scale(self.min_distance, "distance min_distance", allow_zero=True)
        if not self.name:
            object.__setattr__(self, "name", f"distance-{self.sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        tx, ty, tz = params.pose.translation
        vz = float(params.view.translation[2])
        d = vz - float(tz)
        if not d > self.min_distance:
            raise InputError(
                f"distance move needs the face more than {self.min_distance:g} mm in front "
                f"of the camera, got d = {d:g}"
            )
        d_new = d + rng.normal(0.0, self.sigma)
        if d_new < self.min_distance:
            d_new = 2.0 * self.min_distance - d_new
        ratio = d_new / d
        pose = params.pose._replace(translation=(float(tx), float(ty), vz - d_new))
        cam = params.camera._replace(focal_length=float(params.camera.focal_length * ratio))
        return Move(params._replace(pose=pose, camera=cam), float(np.log(ratio)),
                    Block.POSE | Block.CAMERA, self.name)


@dataclass(frozen=True)
class FocalScaling:
    """Zoom: ``f' = f exp(N(0, sigma))``.

    Notes
    -----
    ``q(f'|f) = phi_sigma(log f' - log f) / f'``, so
    ``q(f|f') / q(f'|f) = f' / f``: ``log_q_ratio = log f' - log f``.
    """

    sigma: float
    name: str = ""
    touches: ClassVar[Block] = Block.CAMERA

    def __post_init__(self) -> None:
        """Validate the scale and set a default name."""
        check_scale(self.sigma, "focal scaling sigma")
        if not self.name:
            object.__setattr__(self, "name", f"focal-{self.sigma:g}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        eps = rng.normal(0.0, self.sigma)
        cam = params.camera._replace(focal_length=float(params.camera.focal_length * np.exp(eps)))
        return Move(params._replace(camera=cam), float(eps), Block.CAMERA, self.name)


def _eye(point: np.ndarray, params: RenderParameter) -> np.ndarray:
    return to_eye(np.asarray(point, np.float64).reshape(1, 3), params.pose, params.view)


def _pixel(eye: np.ndarray, params: RenderParameter) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        px, _ = project_eye(eye, params.camera, params.image_size)
    return px[0]


@dataclass(frozen=True)
class ImageCentered:
    """Wrap a proposal so that an anchor point keeps its pixel (shifts the principal point).

    Parameters
    ----------
    inner : Proposal
        A proposal that does not change the principal point (pose, distance,
        focal scaling, or a mixture of them).
    anchor : callable ``(RenderParameter) -> (3,) float array``
        The anchor's model-frame position (mm) for a state, e.g. a landmark's
        vertex at that state's shape and expression. It must not depend on the
        principal point.
    label : str
        Appended to the inner move's name: ``"<inner>@<label>"``.

    Notes
    -----
    After the inner move x -> x', with ``(du, dv)`` the change of the anchor's
    pixel, the principal point (NDC) becomes ``pp_x - 2 du / W``,
    ``pp_y + 2 dv / H``: by ``u = W/2 (1 + pp_x) + u0`` and
    ``v = H/2 (1 - pp_y) + v0`` (``u0, v0`` independent of pp) the anchor is then
    exactly on its old pixel. Touches the inner blocks | CAMERA.

    Ratio: the shift ``h(x, x') = pp' - pp`` depends on the other coordinates
    only and is antisymmetric, ``h(x', x) = -h(x, x')`` (the reverse inner move
    puts the anchor back), so the combined map is the inner move followed by a
    shear in pp: unit Jacobian, and the reverse move exists. Hence
    ``log_q_ratio`` equals the inner ratio. If the anchor cannot be projected
    (it lies in the eye plane z = 0, or is NaN) the move is returned with ratio
    -inf: from such a state no move is ever accepted in either direction, which
    is a (legitimate) rejection rather than an error.
    """

    inner: Proposal
    anchor: Callable[[RenderParameter], np.ndarray]
    label: str = "anchor"
    name: str = ""
    touches: Block = field(init=False)

    def __post_init__(self) -> None:
        """Set ``touches`` (the inner proposal's plus CAMERA) and a default name."""
        object.__setattr__(self, "touches", self.inner.touches | Block.CAMERA)
        if not self.name:
            object.__setattr__(self, "name", f"{self.inner.name}@{self.label}")

    def __call__(self, rng: np.random.Generator, state: ProposalState) -> Move:
        """Draw a move from the accepted ``state`` (not modified) with ``rng``."""
        params = state.params
        move = self.inner(rng, state)
        new = move.params
        p_old = self.anchor(params)
        eye_old = _eye(p_old, params)
        if move.touched & Block.GEOMETRY:
            eye_new = _eye(self.anchor(new), new)
        elif move.touched & Block.POSE:
            eye_new = _eye(p_old, new)
        else:  # camera-only move: the anchor's eye coordinates are unchanged
            eye_new = eye_old
        du, dv = _pixel(eye_new, new) - _pixel(eye_old, params)
        name = f"{move.name}@{self.label}"
        if not (np.isfinite(du) and np.isfinite(dv)):
            return Move(new, -np.inf, move.touched, name)
        if du == 0.0 and dv == 0.0:
            return move._replace(name=name)
        w, h = new.image_size.width, new.image_size.height
        ppx, ppy = new.camera.principal_point
        cam = new.camera._replace(principal_point=(float(ppx - 2.0 * du / w),
                                                   float(ppy + 2.0 * dv / h)))
        return Move(new._replace(camera=cam), move.log_q_ratio, move.touched | Block.CAMERA, name)
