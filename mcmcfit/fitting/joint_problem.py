"""The data and settings of a joint fit of several photographs of one face (picklable).

A :class:`JointProblem` holds one single-image
:class:`~mcmcfit.fitting.problem.FitProblem` per photograph (its image,
landmarks, pose guess and layout), the joint start and the joint column
layout. :class:`JointNoise` is the noise model of every image (each image's
likelihood has its own scale, measured on its own residuals).

This module imports :mod:`albedo_model.errors`, :mod:`mcmcfit.fitting.config`,
:mod:`mcmcfit.fitting.problem`, :mod:`mcmcfit.sampling.joint_layout`,
:mod:`mcmcfit.targets.noise_model` and :mod:`proposals.joint`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from albedo_model.errors import InputError
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.problem import FitProblem
from mcmcfit.sampling.joint_layout import JointParamLayout
from mcmcfit.targets.noise_model import NoiseModel
from proposals.joint import JointParameter

__all__ = ["JointNoise", "JointProblem"]


@dataclass(frozen=True)
class JointProblem:
    """A joint fit's data: one problem per image, the joint start and layout.

    Attributes
    ----------
    images : tuple of FitProblem
        Per photograph; their ``start`` is that image's pose guess.
    config : FitConfig
    start : JointParameter
        The images' pose guesses with one identity (zero coefficients).
    layout : JointParamLayout
    """

    images: tuple[FitProblem, ...]
    config: FitConfig
    start: JointParameter
    layout: JointParamLayout

    def __post_init__(self) -> None:
        """Check that the images and the start agree."""
        if len(self.images) != self.start.n_images or not self.images:
            raise InputError(f"{len(self.images)} image problems for a start of "
                             f"{self.start.n_images} images")

    @property
    def model(self):
        """The morphable model (the same for every image)."""
        return self.images[0].model

    @property
    def n_images(self) -> int:
        """Number of photographs."""
        return len(self.images)


class JointNoise(NamedTuple):
    """The noise model of every image of a joint fit.

    ``sigma`` and ``temperature`` are the images' values as lists (what the fit
    driver records per round); :attr:`images` holds the models themselves.
    """

    images: tuple[NoiseModel, ...]

    @property
    def sigma(self) -> list[float]:
        """Every image's pixel sd."""
        return [float(n.sigma) for n in self.images]

    @property
    def temperature(self) -> list[float]:
        """Every image's temperature."""
        return [float(n.temperature) for n in self.images]

    def to_dict(self) -> dict:
        """Per image, :meth:`NoiseModel.to_dict` (``summary.json``)."""
        return {"images": [n.to_dict() for n in self.images]}
