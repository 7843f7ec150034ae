"""albedo_model: the morphable albedo model and how it forms an image.

PCA parts, the morphable model, its face regions (``regions``), scene parameters (and
all their continuous entries as one vector, ``scene_vector``),
file formats (``io``), the
Embree ray caster and the JAX shading. This is the lowest package: it imports
nothing from ``pipeline``, ``proposals`` or ``mcmcfit``.

This module imports :mod:`albedo_model.errors`, :mod:`albedo_model.model` and
:mod:`albedo_model.pca`.
"""

from albedo_model.errors import AlbedoModelError, FormatError, InputError
from albedo_model.model import ModelCoefficients, MorphableModel, vertex_normals
from albedo_model.pca import PCAPart, pca_from_data

__all__ = [
    "AlbedoModelError", "FormatError", "InputError", "ModelCoefficients", "MorphableModel",
    "PCAPart", "pca_from_data", "vertex_normals",
]
