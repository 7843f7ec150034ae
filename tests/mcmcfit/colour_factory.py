"""A small model whose colour is an sRGB texture (BFM-like), with a scene of known linear albedo."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.io.colour_space import colour_space_metadata, decode_texture, encode_texture
from albedo_model.model import MorphableModel
from albedo_model.pca import PCAPart
from albedo_model.render.renderer import Renderer
from mcmcfit.outputs.posterior import visible_vertices


class SrgbCase(NamedTuple):
    """An sRGB-texture model, a photograph of one of its faces and that face's linear albedo."""

    model: MorphableModel        # colour = encoded texture, metadata says "srgb"
    image: np.ndarray            # (H, W, 3) gamma-encoded photograph
    clicks: dict                 # visible landmarks
    true_linear: np.ndarray      # (n, 3) the face's linear albedo
    visible: np.ndarray          # (n,) vertices seen in the true view


def srgb_texture_model(linear: MorphableModel) -> MorphableModel:
    """``linear`` with its diffuse part sRGB-encoded: mean encoded, basis through the curve's slope."""
    d = linear.diffuse
    h = 1e-4
    slope = (encode_texture(d.mean + h) - encode_texture(d.mean - h)) / (2 * h)
    u, s, _ = np.linalg.svd(slope[:, None] * d.scaled_basis, full_matrices=False)
    part = PCAPart(encode_texture(d.mean), u, s ** 2, 0.0)
    return dataclasses.replace(linear, diffuse=part, metadata=colour_space_metadata("srgb"))


def srgb_case(coefficients=(1.0, -0.8, 0.5), size: int = 64) -> SrgbCase:
    """A photograph (pure 2.2 gamma, SH light) of the decoded texture of one face of the model."""
    model = srgb_texture_model(small_face_model(specular=False))
    d = model.diffuse
    texture = d.mean + d.scaled_basis @ np.asarray(coefficients, float)
    true_linear = decode_texture(texture).reshape(-1, 3)
    truth_model = dataclasses.replace(
        model, diffuse=PCAPart(true_linear.reshape(-1), d.basis, d.variance, 0.0),
        metadata={})
    params = scene(size, size, yaw=0.25, pitch=-0.1)
    image, clicks = synthetic_target(truth_model, params)
    renderer = Renderer(truth_model, specular=False, threads=1)
    visible = visible_vertices(renderer, renderer.init_state(params))
    return SrgbCase(model, image, clicks, true_linear, visible)
