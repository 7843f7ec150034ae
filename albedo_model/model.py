"""The morphable albedo model: reference mesh, PCA parts, landmarks, symmetry.

Diffuse and specular albedo are driven by one shared coefficient vector by
default (AlbedoMM's "transferred" model); ``shared_albedo=False`` gives them
independent coefficient vectors. A plain colour MoMo (BFM 2017) is a model whose
``diffuse`` part is its colour part and whose ``specular`` part is ``None``.

The albedo parts may carry a per-vertex, per-channel residual variance (what
the model cannot represent, estimated out of sample when it was built):
:attr:`MorphableModel.albedo_residual_variance`.

A model may carry texture coordinates (:class:`~albedo_model.uv_atlas.UVAtlas`), to bake
per-vertex values into texture images.

This module imports only :mod:`albedo_model.pca`, :mod:`albedo_model.uv_atlas` and
:mod:`albedo_model.errors`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from functools import cached_property
from typing import NamedTuple

import numpy as np

from albedo_model.errors import InputError
from albedo_model.pca import PCAPart, _readonly
from albedo_model.uv_atlas import UVAtlas

__all__ = ["MorphableModel", "ModelCoefficients", "vertex_normals"]


class ModelCoefficients(NamedTuple):
    """Standard-normal coefficients of a model instance (missing entries are 0).

    Attributes
    ----------
    shape, expression, albedo : (j,) float arrays
        ``albedo`` drives the diffuse part, and the specular part too when the
        model shares albedo coefficients.
    specular : (j,) float array or None
        Independent specular coefficients (only for ``shared_albedo=False``).
    """

    shape: np.ndarray
    expression: np.ndarray
    albedo: np.ndarray
    specular: np.ndarray | None = None

    @classmethod
    def zeros(cls, model: MorphableModel) -> ModelCoefficients:
        """All-zero coefficients of full rank for ``model``."""
        ranks = model.ranks
        spec = None if model.shared_albedo or model.specular is None else np.zeros(ranks["specular"])
        return cls(
            np.zeros(ranks["shape"]), np.zeros(ranks.get("expression", 0)),
            np.zeros(ranks["diffuse"]), spec,
        )


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Compute unit vertex normals as the renormalised mean of adjacent unit face normals.

    Parameters
    ----------
    vertices : (n, 3) float array
    triangles : (m, 3) int array

    Returns
    -------
    (n, 3) float array
        Counter-clockwise triangles give outward normals. Isolated vertices and
        degenerate neighbourhoods get (0, 0, 1) instead of NaN.

    Notes
    -----
    This is the scalismo convention (unweighted mean of unit face normals).
    """
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles)
    fn = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    norm = np.linalg.norm(fn, axis=1, keepdims=True)
    fn = np.divide(fn, norm, out=np.zeros_like(fn), where=norm > 0)
    acc = np.zeros_like(v)
    for j in range(3):
        for c in range(3):
            acc[:, c] += np.bincount(t[:, j], weights=fn[:, c], minlength=len(v))
    n = np.linalg.norm(acc, axis=1, keepdims=True)
    out = np.divide(acc, n, out=np.zeros_like(acc), where=n > 1e-12)
    out[n[:, 0] <= 1e-12] = (0.0, 0.0, 1.0)
    return out.astype(np.asarray(vertices).dtype if np.asarray(vertices).dtype.kind == "f" else np.float64)


@dataclasses.dataclass(frozen=True, eq=False)
class MorphableModel:
    """A 3D morphable model with diffuse (and optional specular) albedo.

    Parameters
    ----------
    vertices : (n, 3) float array
        Reference mesh points (model frame, mm). Written as the representer points.
    triangles : (m, 3) int array
        0-based, counter-clockwise seen from outside.
    shape : PCAPart
        Vertex positions, dimension 3n, interleaved.
    diffuse : PCAPart
        Diffuse albedo (linear sRGB for AlbedoMM), dimension 3n, interleaved.
    expression : PCAPart, optional
        Additive expression displacements (its mean is added too).
    specular : PCAPart, optional
        Specular albedo.
    shared_albedo : bool
        One coefficient vector drives diffuse and specular (default). Requires
        equal ranks, as in AlbedoMM.
    landmarks : mapping of str to (3,) arrays
        Named 3D landmarks in the model frame (Basel names), as stored in the file.
    symmetry : (n,) int array, optional
        Vertex ``i`` is the mirror image of vertex ``symmetry[i]``.
    metadata : mapping of str to str
        Colour space, gamma convention, provenance, ...
    uv_atlas : UVAtlas, optional
        Texture coordinates of the reference mesh's triangles.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    shape: PCAPart
    diffuse: PCAPart
    expression: PCAPart | None = None
    specular: PCAPart | None = None
    shared_albedo: bool = True
    landmarks: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)
    symmetry: np.ndarray | None = None
    metadata: Mapping[str, str] = dataclasses.field(default_factory=dict)
    uv_atlas: UVAtlas | None = None

    def __post_init__(self) -> None:
        """Validate the fields and store read-only, normalised copies of them."""
        v = np.asarray(self.vertices)
        t = np.asarray(self.triangles)
        if v.ndim != 2 or v.shape[1] != 3:
            raise InputError(f"vertices must have shape (n, 3), got {v.shape}")
        if t.ndim != 2 or t.shape[1] != 3:
            raise InputError(f"triangles must have shape (m, 3), got {t.shape}")
        if t.size and (t.min() < 0 or t.max() >= len(v)):
            raise InputError(f"triangle indices out of range [0, {len(v)})")
        if not np.all(np.isfinite(v)):
            raise InputError("vertices contain NaN or infinite values")
        n3 = 3 * len(v)
        for name in ("shape", "diffuse", "expression", "specular"):
            part = getattr(self, name)
            if part is not None and part.dim != n3:
                raise InputError(f"{name} part has dimension {part.dim}, expected 3 x {len(v)} = {n3}")
        if self.shared_albedo and self.specular is not None and self.specular.rank != self.diffuse.rank:
            raise InputError(
                f"shared albedo coefficients need equal ranks: diffuse {self.diffuse.rank}, "
                f"specular {self.specular.rank}"
            )
        if self.symmetry is not None:
            s = np.asarray(self.symmetry)
            if s.shape != (len(v),) or s.min() < 0 or s.max() >= len(v):
                raise InputError(f"symmetry map must be an index array of shape ({len(v)},)")
            object.__setattr__(self, "symmetry", _readonly(s.astype(np.int64)))
        lms = {}
        for name, p in dict(self.landmarks).items():
            p = np.asarray(p, np.float64)
            if p.shape != (3,):
                raise InputError(f"landmark {name!r} must be a 3D point, got shape {p.shape}")
            lms[str(name)] = _readonly(p)
        object.__setattr__(self, "landmarks", lms)
        object.__setattr__(self, "vertices", _readonly(v))
        object.__setattr__(self, "triangles", _readonly(t.astype(np.int32)))
        object.__setattr__(self, "metadata", {str(k): str(x) for k, x in dict(self.metadata).items()})
        if self.uv_atlas is not None:
            if not isinstance(self.uv_atlas, UVAtlas):
                raise InputError(f"uv_atlas must be a UVAtlas, got {type(self.uv_atlas).__name__}")
            self.uv_atlas.check_mesh(t, len(v))

    # -- sizes ---------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        """Number of vertices of the reference mesh."""
        return int(self.vertices.shape[0])

    @property
    def n_triangles(self) -> int:
        """Number of triangles of the reference mesh."""
        return int(self.triangles.shape[0])

    @property
    def ranks(self) -> dict[str, int]:
        """Rank of every present part, by name."""
        return {
            name: getattr(self, name).rank
            for name in ("shape", "expression", "diffuse", "specular")
            if getattr(self, name) is not None
        }

    @property
    def albedo_residual_variance(self) -> dict[str, np.ndarray | None]:
        """Per-vertex residual variance of the albedo parts, (n, 3) float64 or None.

        Keys ``diffuse`` and ``specular`` (``None`` when the part is absent or
        has no residual variance; see :attr:`PCAPart.residual_variance`).
        """
        out: dict[str, np.ndarray | None] = {}
        for name in ("diffuse", "specular"):
            part = getattr(self, name)
            r = None if part is None else part.residual_variance
            out[name] = None if r is None else r.astype(np.float64).reshape(-1, 3)
        return out

    # -- landmarks -----------------------------------------------------------
    @cached_property
    def landmark_vertices(self) -> dict[str, int]:
        """Landmark name -> reference vertex index.

        A landmark resolves to a vertex on an exact coordinate match (scalismo's
        rule) or, failing that, to the nearest vertex within 1e-3 mm (float32
        rounding of files written elsewhere). Others stay unresolved.
        """
        out: dict[str, int] = {}
        if not self.landmarks:
            return out
        v = self.vertices.astype(np.float64)
        for name, p in self.landmarks.items():
            d2 = np.einsum("ij,ij->i", v - p, v - p)
            i = int(np.argmin(d2))
            if d2[i] <= 1e-6:
                out[name] = i
        return out

    # -- instances -----------------------------------------------------------
    def shape_instance(
        self, shape: np.ndarray | None = None, expression: np.ndarray | None = None
    ) -> np.ndarray:
        """Vertex positions (n, 3) float64 for shape and expression coefficients."""
        flat = self.shape.instance(shape)
        if self.expression is not None:
            flat = flat + self.expression.instance(expression)
        elif expression is not None and np.any(np.asarray(expression) != 0):
            raise InputError("the model has no expression part")
        return flat.reshape(-1, 3)

    def diffuse_instance(self, albedo: np.ndarray | None = None) -> np.ndarray:
        """Per-vertex diffuse albedo (n, 3) float64."""
        return self.diffuse.instance(albedo).reshape(-1, 3)

    def specular_instance(
        self, albedo: np.ndarray | None = None, specular: np.ndarray | None = None
    ) -> np.ndarray | None:
        """Per-vertex specular albedo (n, 3), or ``None`` without a specular part.

        With shared coefficients ``albedo`` drives it (padded/truncated to its
        rank); otherwise ``specular``.
        """
        if self.specular is None:
            return None
        c = albedo if self.shared_albedo else specular
        if c is not None and self.shared_albedo:
            c = np.asarray(c, float)[: self.specular.rank]
        return self.specular.instance(c).reshape(-1, 3)

    def instance(self, coefficients: ModelCoefficients) -> dict[str, np.ndarray | None]:
        """All per-vertex attributes: ``vertices``, ``normals``, ``diffuse``, ``specular``."""
        verts = self.shape_instance(coefficients.shape, coefficients.expression)
        return {
            "vertices": verts,
            "normals": vertex_normals(verts, self.triangles),
            "diffuse": self.diffuse_instance(coefficients.albedo),
            "specular": self.specular_instance(coefficients.albedo, coefficients.specular),
        }

    def truncate(self, **ranks: int) -> MorphableModel:
        """Return a copy with parts truncated, e.g. ``model.truncate(shape=50, diffuse=50)``.

        With shared albedo coefficients, truncating ``diffuse`` truncates ``specular``.
        """
        changes: dict[str, PCAPart] = {}
        for name, k in ranks.items():
            part = getattr(self, name, None)
            if not isinstance(part, PCAPart):
                raise InputError(f"model has no part {name!r}")
            changes[name] = part.truncate(min(k, part.rank))
        if self.shared_albedo and self.specular is not None and "diffuse" in ranks:
            changes["specular"] = self.specular.truncate(changes["diffuse"].rank)
        return dataclasses.replace(self, **changes)
