"""A baked-texture comparison model, built the way BFM 2017's colour model was.

BFM 2017's colour is not albedo: it is the texture a camera recorded of each
scanned face under the scanner's fixed lights, shading and highlights baked
in, gamma-encoded. :func:`bake_textures` makes such textures of the same
training subjects the intrinsic model is built from: per vertex on the
template head, ``clip(D * shading(n) + S * highlight(n))`` under a fixed,
non-uniform light (ambient, a key light from above one side, its Blinn-Phong
highlight for a frontal camera), encoded with the sRGB curve as a camera
would (:func:`albedo_model.io.colour_space.encode_texture`).
:func:`build_baked_model` takes their PCA to the intrinsic model's rank
(no mirror augmentation: the baked light is not symmetric) and returns a
colour-only model marked ``colour_space`` ``srgb`` (fitted as the reference
does: the model's colour is the camera's value) or, with
``colour="linear"``, the PCA of the decoded textures marked linear (the
paper's "we applied gamma for both models").

This module imports :mod:`albedo_model` (model, PCA, colour space).
"""

from __future__ import annotations

import dataclasses
import json
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.io.colour_space import colour_space_metadata, decode_texture, encode_texture
from albedo_model.model import MorphableModel, vertex_normals
from albedo_model.pca import pca_from_data

__all__ = ["BAKED_LIGHT", "BakedLight", "bake_textures", "build_baked_model"]


class BakedLight(NamedTuple):
    """The fixed light of the baked textures (model frame, camera looking along -z).

    Attributes
    ----------
    ambient : float
        Uniform part.
    key : float
        Strength of the directional key light.
    direction : (3,) tuple
        Towards the key light.
    highlight : float
        Strength of its Blinn-Phong highlight.
    shininess : float
        Blinn-Phong exponent.
    """

    ambient: float = 0.45
    key: float = 0.75
    direction: tuple = (-0.45, 0.55, 0.70)
    highlight: float = 0.5
    shininess: float = 20.0


#: The light of :func:`bake_textures` by default.
BAKED_LIGHT = BakedLight()


def bake_textures(diffuse: np.ndarray, specular: np.ndarray, normals: np.ndarray,
                  light: BakedLight = BAKED_LIGHT) -> np.ndarray:
    """Return camera textures (gamma-encoded sRGB) of albedo maps under a fixed light.

    Parameters
    ----------
    diffuse, specular : (S, n, 3) or (n, 3) float arrays, linear sRGB
    normals : (n, 3) float array
        Unit vertex normals of the head the maps belong to.
    light : BakedLight

    Returns
    -------
    array like ``diffuse``
        ``encode(clip(D * (ambient + key max(0, n.l)) + S * highlight (n.h)^shininess, 0, 1))``
        with ``h`` the half vector of ``l`` and the frontal view ``(0, 0, 1)``.
    """
    d = np.asarray(diffuse, np.float64)
    s = np.asarray(specular, np.float64)
    n = np.asarray(normals, np.float64)
    if d.shape != s.shape or d.shape[-2:] != n.shape:
        raise InputError(f"maps {d.shape}, {s.shape} and normals {n.shape} do not match")
    lvec = np.asarray(light.direction, np.float64)
    lvec /= np.linalg.norm(lvec)
    half = lvec + np.array([0.0, 0.0, 1.0])
    half /= np.linalg.norm(half)
    lambert = np.maximum(0.0, n @ lvec)
    shade = light.ambient + light.key * lambert
    gloss = light.highlight * np.where(lambert > 0, np.maximum(0.0, n @ half), 0.0) ** light.shininess
    linear = np.clip(d * shade[:, None] + s * gloss[:, None], 0.0, 1.0)
    return encode_texture(linear)


def build_baked_model(intrinsic: MorphableModel, subjects, rank: int, *,
                      colour: str = "srgb", light: BakedLight = BAKED_LIGHT) -> MorphableModel:
    """Colour-only model of the subjects' baked textures, on the intrinsic model's geometry.

    Parameters
    ----------
    intrinsic : MorphableModel
        Supplies the mesh, shape, expression, landmarks and symmetry (the
        experiment compares albedo models only).
    subjects : sequence of Subject
        The training subjects (``diffuse``, ``specular``).
    rank : int
        Components kept (the intrinsic model's rank).
    colour : {"srgb", "linear"}
        ``"srgb"``: PCA of the encoded textures, marked sRGB (BFM's way);
        ``"linear"``: PCA of the decoded textures, marked linear.
    light : BakedLight

    Returns
    -------
    MorphableModel
        ``specular`` None; metadata ``colour_space``, ``baked_light`` and provenance.
    """
    if colour not in ("srgb", "linear"):
        raise InputError(f"colour must be 'srgb' or 'linear', got {colour!r}")
    normals = vertex_normals(np.asarray(intrinsic.vertices, np.float64), intrinsic.triangles)
    d = np.stack([np.asarray(s.diffuse) for s in subjects])
    sp = np.stack([np.asarray(s.specular) for s in subjects])
    tex = bake_textures(d, sp, normals, light)
    if colour == "linear":
        tex = decode_texture(tex)
    part = pca_from_data(tex.reshape(len(subjects), -1), rank=min(int(rank), len(subjects) - 1))
    part = dataclasses.replace(part, mean=part.mean.astype(np.float32),
                               basis=part.basis.astype(np.float32),
                               variance=part.variance.astype(np.float32))
    metadata = {
        "synthetic": "true",
        "description": "baked-texture comparison model (BFM 2017's way: camera textures of "
                       "the training subjects under a fixed light, shading and highlights "
                       "baked in" + (", decoded to linear)" if colour == "linear" else ")"),
        **colour_space_metadata(colour),
        "baked_light": json.dumps(light._asdict()),
        "provenance": json.dumps({"builder": "pipeline.synthetic.baked_model",
                                  "subjects": len(subjects), "rank": part.rank,
                                  "colour": colour}),
    }
    return dataclasses.replace(intrinsic, diffuse=part, specular=None, shared_albedo=True,
                               metadata=metadata)
