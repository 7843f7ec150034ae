"""The built-in default model: synthetic lightstage -> AlbedoMM HDF5, cached.

``build_default_model`` runs the whole synthetic pipeline deterministically:
procedural template head, Gaussian-process shape model and expression modes,
spectral-skin subjects, symmetry-augmented PCA of diffuse and specular albedo
(the paper's "transferred" variant: one shared coefficient vector) with the
per-vertex residual variance of both albedo parts estimated by leave-one-out
over the subjects (:mod:`pipeline.modelling.residual_variance`: what the
model cannot represent of an unseen face), and returns a
:class:`MorphableModel` whose metadata marks it synthetic. The file is written
in the AlbedoMM layout, so it is read by the same loader as AlbedoMM/BFM files.

This module imports :mod:`albedo_model`; :mod:`pipeline.lightstage.colour`,
:mod:`pipeline.modelling.pca_variants`, :mod:`pipeline.modelling.residual_variance`,
:mod:`pipeline.synthetic.subjects` and
:mod:`pipeline.synthetic.head` modules are imported when the model is built.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from albedo_model.default_model import BUILD_VERSION, default_model_path
from albedo_model.model import MorphableModel
from albedo_model.pca import PCAPart
from albedo_model.uv_atlas import compute_uv_atlas

__all__ = ["DEFAULT_RANKS", "DEFAULT_SEED", "DEFAULT_SUBJECTS", "build_default_model",
           "build_model_from_subjects", "ensure_default_model"]

DEFAULT_SEED = 2020
DEFAULT_SUBJECTS = 60
DEFAULT_RANKS = {"shape": 40, "albedo": 50}
_STAGES = ("template head", "shape and expression model", "synthetic subjects",
           "albedo PCA", "UV atlas", "writing")


def _float32(part: PCAPart) -> PCAPart:
    residual = part.residual_variance
    return PCAPart(part.mean.astype(np.float32), part.basis.astype(np.float32),
                   part.variance.astype(np.float32), part.noise_variance,
                   None if residual is None else residual.astype(np.float32))


def build_default_model(
    *,
    seed: int = DEFAULT_SEED,
    n_subjects: int = DEFAULT_SUBJECTS,
    shape_rank: int = DEFAULT_RANKS["shape"],
    albedo_rank: int = DEFAULT_RANKS["albedo"],
    progress: Callable[[str], None] | None = None,
) -> MorphableModel:
    """Build the synthetic default model (deterministic for a seed).

    Parameters
    ----------
    seed : int
        Seeds the shape model and the subjects.
    n_subjects : int
        Synthetic subjects; each is used twice (mirrored), so the albedo rank is
        at most ``2 n_subjects - 1``.
    shape_rank, albedo_rank : int
        Ranks kept.
    progress : callable, optional
        Called with the name of each stage (see ``_STAGES``) as it starts.

    Returns
    -------
    MorphableModel
        Float32 parts, shared albedo coefficients, the albedo parts' leave-one-out
        residual variances, symmetry map, the template's Basel landmarks, and
        metadata (``synthetic``, colour space, gamma, seed; the provenance
        records the residual variance's estimate and its RMS per channel), and a
        UV atlas of the template head (:func:`albedo_model.uv_atlas.compute_uv_atlas`).
    """
    from pipeline.synthetic.head.shape_model import build_expression_model, build_shape_model
    from pipeline.synthetic.subjects import make_subjects
    from pipeline.synthetic.head.template_head import build_template_head

    say = progress or (lambda stage: None)
    say(_STAGES[0])
    head = build_template_head()
    say(_STAGES[1])
    shape = build_shape_model(head, rank=shape_rank, seed=seed)
    expression = build_expression_model(head)
    say(_STAGES[2])
    subjects = make_subjects(head, n_subjects, seed)
    say(_STAGES[3])
    model = build_model_from_subjects(head, shape, expression, subjects, seed=seed,
                                      albedo_rank=albedo_rank)
    say(_STAGES[4])
    return dataclasses.replace(model, uv_atlas=compute_uv_atlas(model.vertices, model.triangles))


def build_model_from_subjects(
    head,
    shape: PCAPart,
    expression: PCAPart,
    subjects,
    *,
    seed: int,
    albedo_rank: int = DEFAULT_RANKS["albedo"],
    builder: str = "pipeline.synthetic.default_model",
    extra_provenance: dict | None = None,
) -> MorphableModel:
    """Build the albedo model of ``subjects`` on the template ``head`` (the default model's recipe).

    Parameters
    ----------
    head : TemplateHead
        Template head (vertices, triangles, symmetry, landmarks).
    shape, expression : PCAPart
        Shape and expression parts of the model.
    subjects : sequence of Subject
        Training subjects (their ``diffuse`` and ``specular`` maps, linear sRGB).
    seed : int
        Population seed (recorded in the provenance).
    albedo_rank : int
        Albedo components kept.
    builder : str
        Name recorded as the provenance's ``builder``.
    extra_provenance : dict, optional
        More provenance entries (e.g. the held-out subjects).

    Returns
    -------
    MorphableModel
        As :func:`build_default_model` describes.
    """
    from pipeline.modelling.pca_variants import build_albedo_parts
    from pipeline.modelling.residual_variance import (
        attach_residual_variance,
        loo_residual_variance,
        residual_rms_per_channel,
    )
    from pipeline.lightstage.colour import camera_colour

    diffuse = np.stack([s.diffuse for s in subjects])
    specular = np.stack([s.specular for s in subjects])
    parts = build_albedo_parts(diffuse, specular, head.symmetry, variant="transferred",
                               rank=albedo_rank)
    residual = loo_residual_variance(diffuse, specular, head.symmetry, variant="transferred",
                                     rank=albedo_rank)
    parts = attach_residual_variance(parts, residual)
    verts = head.vertices.astype(np.float32)
    provenance = {
        "builder": builder, "build_version": BUILD_VERSION, "seed": seed,
        "subjects": len(subjects), "variant": "transferred", "symmetry_augmented": True,
        "camera_colour": camera_colour().metadata(),
        "residual_variance": {
            "estimate": "leave-one-out over the subjects (each held out with its mirror image), "
                        "models of the others at the same rank, mean squared residual per "
                        "vertex and channel",
            "rank": residual.rank, "held_out_samples": residual.n_held_out,
            "rms_diffuse_rgb": [round(float(v), 6)
                                for v in residual_rms_per_channel(residual.diffuse)],
            "rms_specular_rgb": [round(float(v), 6)
                                 for v in residual_rms_per_channel(residual.specular)],
        },
        **(extra_provenance or {}),
    }
    metadata = {
        "synthetic": "true",
        "description": "mcmcfit built-in synthetic demonstration model (not a real face model)",
        "colour_space": "linear sRGB",
        "gamma": "pure power 2.2 (AlbedoMM convention)",
        "provenance": json.dumps(provenance, sort_keys=True, default=str),
    }
    return MorphableModel(
        verts, head.triangles, _float32(shape), _float32(parts.diffuse),
        expression=_float32(expression), specular=_float32(parts.specular),
        shared_albedo=parts.shared,
        landmarks={name: verts[i].astype(np.float64) for name, i in head.landmarks.items()},
        symmetry=head.symmetry, metadata=metadata,
    )


#: Modules whose code determines the default model's content.
_BUILDER_MODULES = ("synthetic.default_model", "synthetic.head.template_head",
                    "synthetic.head.head_sdf", "synthetic.head.landmarks",
                    "synthetic.head.regions", "synthetic.head.shape_model",
                    "synthetic.subjects", "synthetic.skin_spectral", "lightstage.colour",
                    "modelling.pca_variants", "modelling.symmetry",
                    "modelling.generalisation", "modelling.residual_variance")


def default_model_fingerprint() -> str:
    """Hash of the builder's source code and settings (names the cached file)."""
    h = hashlib.sha256(repr((BUILD_VERSION, DEFAULT_SEED, DEFAULT_SUBJECTS,
                             sorted(DEFAULT_RANKS.items()))).encode())
    package = Path(__file__).resolve().parents[1]  # pipeline/
    for name in _BUILDER_MODULES:
        h.update((package / f"{name.replace('.', '/')}.py").read_bytes())
    return h.hexdigest()[:16]


def ensure_default_model(*, progress: bool = True) -> Path:
    """Path of the cached default model, building and writing it first if needed.

    The file is written atomically, so concurrent first uses cannot leave a
    partial file behind (the last complete write wins; all are identical).
    """
    from albedo_model.io.momo_h5 import write_model_h5

    path = default_model_path(default_model_fingerprint(), must_exist=False)
    if path.is_file():
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(_STAGES), desc="building the default model (once)", unit="stage",
                   leave=False, file=sys.stderr)

    def step(stage: str) -> None:
        if bar is not None:
            bar.n = _STAGES.index(stage)
            bar.set_postfix_str(stage)

    model = build_default_model(progress=step)
    step("writing")
    write_model_h5(model, path)
    if bar is not None:
        bar.close()
        print(f"built the default model in {time.perf_counter() - start:.1f} s: {path}",
              file=sys.stderr)
    return path
