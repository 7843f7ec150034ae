"""Synthetic subjects with ground-truth diffuse and specular albedo per vertex.

Each subject has a Fitzpatrick type (I-VI, balanced over the population), a
skin tone inside that type's band, and per-vertex melanin and blood fraction
maps: smooth random fields on the head (a bilaterally symmetric part and a
smaller asymmetric part), fine per-vertex noise, and regional offsets (more
blood in lips and cheeks, more melanin in brows and, for some subjects, the
beard zone). Diffuse albedo is the spectral skin model of
:mod:`pipeline.synthetic.skin_spectral` seen through the calibrated camera, looked up in
a (melanin, blood) table. Eyeballs get a white-ish sclera (and an iris and
pupil around the ``*.eye.pupil.center`` landmarks when the template has them).
Specular albedo is near-grey with regional levels (forehead and nose highest,
lips and eyeballs high, cheeks medium, brows and beard lowest) and smooth
variation; beard and brows lower it, so it correlates with the diffuse map.

Everything is linear sRGB. Subject ``i`` of seed ``s`` depends only on
``(s, i)``, never on how many subjects are made.

The template is any object with the :class:`HeadTemplate` attributes (in practice
``pipeline.synthetic.head.template_head.TemplateHead``).

This module imports only :mod:`albedo_model.errors` and :mod:`pipeline.synthetic.skin_spectral`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Protocol

import numpy as np
import scipy.sparse as sp

from albedo_model.errors import InputError
from pipeline.synthetic.skin_spectral import (
    REFERENCE_BLOOD, SkinColourTable, fitzpatrick_band, skin_colour_table, tone_melanin,
)

__all__ = [
    "BLUR_PASSES", "HeadTemplate", "Subject", "make_subject", "make_subjects", "region_weights",
]

REGION_KEYS = ("eyeballs", "lips", "brows", "beard", "nose", "forehead", "cheeks", "skin", "ears")

# Regional offsets of ln(melanin) and ln(blood); scaled per subject where noted.
_BLOOD_OFFSET = {"lips": 1.35, "cheeks": 0.45, "nose": 0.3, "ears": 0.25}
_MELANIN_OFFSET = {"brows": 1.0, "beard": 0.9, "lips": -0.15}
# Specular albedo level per region (grey, linear sRGB); "skin" is the default.
_SPECULAR_LEVEL = {
    "forehead": 0.34, "nose": 0.38, "lips": 0.28, "cheeks": 0.22, "ears": 0.16,
    "brows": 0.09, "beard": 0.15, "eyeballs": 0.55, "skin": 0.20,
}
#: Blur passes per region in :func:`region_weights`.
BLUR_PASSES = {"eyeballs": 0, "lips": 1, "brows": 1, "skin": 0, "default": 6}
_SCLERA = np.array([0.68, 0.64, 0.60])
_PUPIL = np.array([0.012, 0.011, 0.010])
_IRIS = {
    "brown": np.array([0.11, 0.055, 0.025]),
    "dark brown": np.array([0.05, 0.027, 0.014]),
    "green": np.array([0.09, 0.11, 0.06]),
    "blue": np.array([0.10, 0.14, 0.20]),
}
_IRIS_RADIUS_MM = 6.0
_PUPIL_RADIUS_MM = 2.0


class HeadTemplate(Protocol):
    """What subject generation needs from a template head (model frame, mm)."""

    vertices: np.ndarray            # (n, 3) float
    triangles: np.ndarray           # (m, 3) int
    symmetry: np.ndarray            # (n,) int, an involution: mirror partner of each vertex
    landmarks: Mapping[str, int]    # name -> vertex index
    regions: Mapping[str, np.ndarray]  # name -> (n,) bool


@dataclasses.dataclass(frozen=True, eq=False)
class Subject:
    """One synthetic subject and the parameters that made it.

    Attributes
    ----------
    index : int
        Position in the population.
    seed : int
        Population seed; the subject draws from ``SeedSequence(seed, spawn_key=(0, index))``.
    fitzpatrick : int
        Skin type 1..6 (I..VI).
    tone : float
        Skin tone in [0, 1] (0 lightest) inside the type's band.
    melanin : (n,) float array
        Epidermal melanin fraction per vertex.
    blood : (n,) float array
        Dermal blood fraction per vertex.
    beard : float
        Beard-shadow strength in [0, 1] (0: none).
    diffuse : (n, 3) float array
        Diffuse albedo, linear sRGB, in [0, 1].
    specular : (n, 3) float array
        Specular albedo, linear sRGB, near-grey, in [0, 1].
    """

    index: int
    seed: int
    fitzpatrick: int
    tone: float
    melanin: np.ndarray
    blood: np.ndarray
    beard: float
    diffuse: np.ndarray
    specular: np.ndarray


def _blur_operator(vertices: np.ndarray, sigma_mm: float) -> sp.csr_matrix:
    """Row-normalised Gaussian weights over vertices closer than ``3 sigma`` (Euclidean)."""
    from scipy.spatial import cKDTree

    v = np.asarray(vertices, float)
    n = len(v)
    tree = cKDTree(v)
    d = tree.sparse_distance_matrix(tree, 3.0 * sigma_mm, output_type="coo_matrix")
    off = d.row != d.col
    rows = np.concatenate([d.row[off], np.arange(n)])
    cols = np.concatenate([d.col[off], np.arange(n)])
    vals = np.concatenate([np.exp(-0.5 * (d.data[off] / sigma_mm) ** 2), np.ones(n)])
    k = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    return sp.diags(1.0 / np.asarray(k.sum(axis=1)).ravel()) @ k


def region_weights(template: HeadTemplate, *, blur_mm: float = 2.0) -> dict[str, np.ndarray]:
    """Soft region masks: each boolean region blurred with Gaussians of ``blur_mm``.

    Large regions (forehead, cheeks, nose, beard, ears) get :data:`BLUR_PASSES`
    passes (an effective width of ``blur_mm * sqrt(passes)``, about 5 mm), thin
    ones (lips, brows) a single pass, eyeballs none.

    Parameters
    ----------
    template : HeadTemplate
    blur_mm : float
        Standard deviation of one pass (Euclidean distance in the model frame,
        so transition widths do not depend on the mesh resolution).

    Returns
    -------
    dict of str to (n,) float arrays in [0, 1]
        Symmetrised with the template's symmetry map. ``eyeballs`` stays a hard
        0/1 mask (the eyeball is its own surface, nothing blends across it).
        Missing regions are all zero.
    """
    n = len(template.vertices)
    blur = _blur_operator(template.vertices, blur_mm) if blur_mm > 0 else sp.identity(n)
    sym = np.asarray(template.symmetry)
    out = {}
    for name in REGION_KEYS:
        mask = template.regions.get(name)
        if mask is None:
            out[name] = np.zeros(n)
            continue
        w = np.asarray(mask, float)
        if w.shape != (n,):
            raise InputError(f"region {name!r} has shape {w.shape}, expected ({n},)")
        for _ in range(BLUR_PASSES.get(name, BLUR_PASSES["default"])):
            w = blur @ w
        out[name] = 0.5 * (w + w[sym])
    return out


class _Fields:
    """Smooth random fields on the vertices: fixed random Fourier features, per-subject weights.

    The features (frequencies ~ N(0, I / length^2)) are drawn once per population,
    so each subject costs one (n, 2F) x (2F,) product per field; the fields are
    draws of a Gaussian process with approximately squared-exponential covariance
    and unit variance.
    """

    def __init__(
        self, vertices: np.ndarray, symmetry: np.ndarray, rng: np.random.Generator,
        lengths_mm: tuple[float, ...] = (40.0, 10.0), n_features: int = 64,
    ) -> None:
        p = np.asarray(vertices, float)
        self.sym = np.asarray(symmetry)
        self.basis = {}
        for length in lengths_mm:
            arg = p @ (rng.standard_normal((3, n_features)) / length)
            self.basis[length] = np.sqrt(1.0 / n_features) * np.hstack([np.cos(arg), np.sin(arg)])

    def smooth(self, rng: np.random.Generator, length_mm: float) -> np.ndarray:
        phi = self.basis[length_mm]
        return phi @ rng.standard_normal(phi.shape[1])

    def symmetric(self, rng: np.random.Generator, length_mm: float) -> np.ndarray:
        g = self.smooth(rng, length_mm)
        return (g + g[self.sym]) / np.sqrt(2.0)


@dataclasses.dataclass(frozen=True)
class _Context:
    weights: Mapping[str, np.ndarray]
    table: SkinColourTable
    fields: _Fields


def _context(template: HeadTemplate, seed: int) -> _Context:
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(1,)))
    return _Context(
        region_weights(template), skin_colour_table(),
        _Fields(template.vertices, template.symmetry, rng),
    )


def _blend(
    weights: Mapping[str, np.ndarray], levels: Mapping[str, float], default: float
) -> np.ndarray:
    total = sum(weights[k] for k in levels)
    acc = sum(weights[k] * v for k, v in levels.items())
    return (acc + np.maximum(0.0, 1.0 - total) * default) / np.maximum(1.0, total)


def _eye_colour(
    template: HeadTemplate, rng: np.random.Generator, fitzpatrick: int
) -> np.ndarray:
    """Per-vertex eyeball colour: sclera, and iris/pupil discs around pupil landmarks."""
    n = len(template.vertices)
    col = np.broadcast_to(_SCLERA * rng.uniform(0.92, 1.05), (n, 3)).copy()
    names = ["brown", "dark brown"] + (["green", "blue"] if fitzpatrick <= 2 else [])
    iris = _IRIS[names[rng.integers(len(names))]] * rng.uniform(0.8, 1.2)
    v = np.asarray(template.vertices, float)
    for side in ("left", "right"):
        idx = template.landmarks.get(f"{side}.eye.pupil.center")
        if idx is None:
            continue
        d = np.linalg.norm(v - v[int(idx)], axis=1)
        col[d < _IRIS_RADIUS_MM] = iris
        col[d < _PUPIL_RADIUS_MM] = _PUPIL
    return col


def make_subject(
    template: HeadTemplate,
    index: int,
    seed: int,
    *,
    context: _Context | None = None,
) -> Subject:
    """Subject ``index`` of the population with seed ``seed`` (see :func:`make_subjects`).

    Parameters
    ----------
    template : HeadTemplate
    index, seed : int
    context : optional
        Per-population precomputation (internal; built when omitted).
    """
    ctx = _context(template, seed) if context is None else context
    w, fields = ctx.weights, ctx.fields
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(0, int(index))))
    n = len(template.vertices)

    fitzpatrick = int(index) % 6 + 1
    lo, hi = fitzpatrick_band(fitzpatrick)
    tone = float(rng.uniform(lo, hi))
    beard = float(rng.uniform(0.3, 1.0)) if rng.uniform() < 0.4 else 0.0
    brow = rng.uniform(0.5, 1.2)
    flush = rng.uniform(0.5, 1.3)

    log_mel = (
        np.log(tone_melanin(tone))
        + 0.08 * fields.symmetric(rng, 40.0) + 0.04 * fields.smooth(rng, 40.0)
        + 0.05 * fields.symmetric(rng, 10.0) + 0.03 * rng.standard_normal(n)
        + brow * _MELANIN_OFFSET["brows"] * w["brows"]
        + beard * _MELANIN_OFFSET["beard"] * w["beard"] * (1 - w["lips"])
        + _MELANIN_OFFSET["lips"] * w["lips"]
    )
    log_blood = (
        np.log(REFERENCE_BLOOD) + rng.normal(0.0, 0.2)
        + 0.15 * fields.symmetric(rng, 40.0) + 0.06 * fields.smooth(rng, 40.0)
        + 0.04 * rng.standard_normal(n)
        + sum((flush if k == "cheeks" else 1.0) * off * w[k] for k, off in _BLOOD_OFFSET.items())
    )
    melanin = np.clip(np.exp(log_mel), 1e-3, 0.8)
    blood = np.clip(np.exp(log_blood), 1e-3, 0.3)
    skin = ctx.table(melanin, blood)
    eye = w["eyeballs"][:, None]
    diffuse = np.clip((1 - eye) * skin + eye * _eye_colour(template, rng, fitzpatrick), 0.0, 1.0)

    levels = dict(_SPECULAR_LEVEL)
    levels["beard"] *= 1.0 - 0.6 * beard
    levels["brows"] *= 1.4 - 0.5 * brow
    default = levels.pop("skin")
    eye_level = levels.pop("eyeballs")
    grey = np.where(w["eyeballs"] > 0.5, eye_level, _blend(w, levels, default)) * np.exp(
        rng.normal(0.0, 0.15) + 0.12 * fields.symmetric(rng, 40.0)
        + 0.05 * fields.smooth(rng, 40.0) + 0.03 * rng.standard_normal(n)
    )
    tint = 1.0 + rng.normal(0.0, 0.015, 3)
    specular = np.clip(grey[:, None] * (tint / tint.mean()), 0.0, 1.0)

    for a in (melanin, blood, diffuse, specular):
        a.setflags(write=False)
    return Subject(
        index=int(index), seed=int(seed), fitzpatrick=fitzpatrick, tone=tone, melanin=melanin,
        blood=blood, beard=beard, diffuse=diffuse, specular=specular,
    )


def make_subjects(template: HeadTemplate, n: int, seed: int) -> list[Subject]:
    """Make a population of ``n`` synthetic subjects, Fitzpatrick types cycling I..VI.

    Parameters
    ----------
    template : HeadTemplate
        Vertices (n_v, 3) mm, triangles, symmetry involution, landmarks and the
        regions ``eyeballs, lips, brows, beard, nose, forehead, cheeks, skin, ears``
        (missing regions count as empty).
    n : int
        Number of subjects.
    seed : int
        Population seed; the same seed gives the same subjects (bit for bit).

    Returns
    -------
    list of Subject
    """
    if n < 0:
        raise InputError(f"number of subjects must be non-negative, got {n}")
    sym = np.asarray(template.symmetry)
    nv = len(template.vertices)
    if sym.shape != (nv,) or not np.array_equal(sym[sym], np.arange(nv)):
        raise InputError("template symmetry must be an involution of shape (n_vertices,)")
    ctx = _context(template, seed)
    return [make_subject(template, i, seed, context=ctx) for i in range(n)]
