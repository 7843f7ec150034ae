"""A population of synthetic subjects split into a model's training set and held-out subjects.

The paper's held-out experiment (Smith et al. 2020, §6): build the albedo
model **without** some identities, then photograph those identities and
compare the recovered albedo with their measured albedo. Here the population
is the synthetic lightstage's (:func:`pipeline.synthetic.subjects.make_subjects`:
subject ``i`` of a seed depends only on ``(seed, i)``), the first
``n_subjects`` train the model with the default model's recipe
(:func:`pipeline.synthetic.default_model.build_model_from_subjects`) and the
next ``n_held_out`` are held out; they get skin detail outside the span of
smooth synthetic faces (:mod:`pipeline.synthetic.skin_detail`). With the
default seed, 60 training subjects and rank 50 the model *is* the built-in
default model, so the cached file is used (no rebuild).

The shape and expression parts are the default model's (the experiment is
about albedo; every model of the evaluation shares them).

This module imports :mod:`albedo_model` and :mod:`pipeline.synthetic` modules
(the template head, subjects, skin detail and the default model's builder).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel
from pipeline.synthetic.default_model import (
    DEFAULT_RANKS,
    DEFAULT_SEED,
    DEFAULT_SUBJECTS,
    build_model_from_subjects,
    ensure_default_model,
)
from pipeline.synthetic.skin_detail import SkinDetail, add_skin_detail
from pipeline.synthetic.subjects import Subject, make_subjects, region_weights

__all__ = ["HeldOutPopulation", "HeldOutSubject", "build_held_out_population",
           "held_out_indices"]


class HeldOutSubject(NamedTuple):
    """One held-out subject: its true maps (with detail) and what made them.

    Attributes
    ----------
    index : int
        Index in the population (>= the number of training subjects).
    fitzpatrick : int
        Skin type 1..6.
    diffuse, specular : (n, 3) float64, linear sRGB
        True albedo, with the skin detail.
    smooth_diffuse : (n, 3) float64
        The subject's diffuse albedo before the detail.
    detail : list of str
        The kinds of detail applied.
    """

    index: int
    fitzpatrick: int
    diffuse: np.ndarray
    specular: np.ndarray
    smooth_diffuse: np.ndarray
    detail: list


class HeldOutPopulation(NamedTuple):
    """The model built without the held-out subjects, its training set and the held-out subjects.

    Attributes
    ----------
    model : MorphableModel
        The intrinsic (linear albedo) model of the training subjects.
    head : TemplateHead
        The template head (regions, symmetry).
    training : list of Subject
        Subjects ``0 .. n_subjects - 1``.
    held_out : list of HeldOutSubject
        Subjects ``n_subjects .. n_subjects + n_held_out - 1``.
    seed : int
        Population seed.
    albedo_rank : int
        Rank of the albedo parts.
    """

    model: MorphableModel
    head: object
    training: list
    held_out: list
    seed: int
    albedo_rank: int


def held_out_indices(n_subjects: int, n_held_out: int) -> list[int]:
    """Return the population indices of the held-out subjects: the ``n_held_out`` after the training set.

    Fitzpatrick types cycle I..VI with the index, so six held-out subjects
    cover every type.
    """
    if n_subjects < 2:
        raise InputError(f"need at least 2 training subjects, got {n_subjects}")
    if n_held_out < 1:
        raise InputError(f"need at least 1 held-out subject, got {n_held_out}")
    return list(range(int(n_subjects), int(n_subjects) + int(n_held_out)))


def _default_geometry() -> MorphableModel:
    from albedo_model.io.model_files import load_model

    return load_model(ensure_default_model(progress=False))


def build_held_out_population(
    n_subjects: int = DEFAULT_SUBJECTS,
    n_held_out: int = 6,
    *,
    seed: int = DEFAULT_SEED,
    albedo_rank: int = DEFAULT_RANKS["albedo"],
    detail: SkinDetail | None = None,
) -> HeldOutPopulation:
    """Build the model of ``n_subjects`` subjects and the ``n_held_out`` subjects it never saw.

    Parameters
    ----------
    n_subjects : int
        Training subjects (indices ``0 .. n_subjects - 1``).
    n_held_out : int
        Held-out subjects (the next indices).
    seed : int
        Population seed (every subject, every detail).
    albedo_rank : int
        Albedo components kept (at most ``2 n_subjects - 1``).
    detail : SkinDetail, optional
        Detail of the held-out subjects (default: every kind; ``SkinDetail.none()``:
        smooth subjects).

    Returns
    -------
    HeldOutPopulation
    """
    from pipeline.synthetic.head.template_head import build_template_head

    detail = SkinDetail() if detail is None else detail
    held = held_out_indices(n_subjects, n_held_out)
    rank = min(int(albedo_rank), 2 * int(n_subjects) - 1)
    head = build_template_head()
    population = make_subjects(head, int(n_subjects) + int(n_held_out), seed)
    training = population[:n_subjects]
    base = _default_geometry()
    if (int(seed), int(n_subjects), rank) == (DEFAULT_SEED, DEFAULT_SUBJECTS,
                                               DEFAULT_RANKS["albedo"]):
        model = base  # the default model is exactly this build
    else:
        model = build_model_from_subjects(
            head, base.shape, base.expression, training, seed=seed, albedo_rank=rank,
            builder="pipeline.synthetic.held_out",
            extra_provenance={"held_out_subjects": held})
    weights = region_weights(head)
    out = []
    for i in held:
        s: Subject = population[i]
        d, sp = add_skin_detail(s.diffuse, s.specular, head, [int(seed), 7, i], detail,
                                weights=weights)
        out.append(HeldOutSubject(i, s.fitzpatrick, d, sp, np.asarray(s.diffuse, np.float64),
                                  detail.enabled()))
    return HeldOutPopulation(model, head, training, out, int(seed), rank)
