"""The colour space of a model's colour parts: linear albedo or a gamma-encoded (sRGB) texture.

AlbedoMM's diffuse and specular albedo (and every model mcmcfit builds) is
**linear** sRGB albedo; BFM 2017's ``/color`` is a texture as a camera saw it,
**gamma-encoded** sRGB. :func:`model_colour_space` decides which one a model
holds, in this order:

1. ``override`` (``--model-colour linear|srgb``, ``FitConfig.model_colour``);
2. the model's metadata: ``colour_space`` (:data:`COLOUR_SPACE_KEY`) naming a
   linear space (``"linear sRGB"``, ``"linear"``) or an encoded one (``"sRGB"``,
   ``"srgb"``, ``"sRGB (gamma-encoded)"``); statismo's bare ``"RGB"`` says
   nothing about the encoding and is passed over, and so is the entry the
   reader adds to files written elsewhere (its guess from the layout);
3. the layout: a diffuse/specular split (AlbedoMM) is linear; a colour-only
   model read from a scalismo MoMo file (BFM 2017) is sRGB;
4. otherwise (a model built in memory, without metadata) linear, as before
   this choice existed.

:func:`decode_texture` and :func:`encode_texture` convert between the two
with the IEC 61966-2-1 sRGB curve, colour-science's
``colour.cctf_decoding`` / ``colour.cctf_encoding`` with ``function="sRGB"``
(the only sRGB transfer function in the project; photographs are linearised
with AlbedoMM's pure power 2.2 instead, :func:`mcmcfit.targets.image.linearise`).

This module imports :mod:`albedo_model.errors` and :mod:`albedo_model.model`
(colour-science is imported when a texture is first converted).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from albedo_model.errors import InputError
from albedo_model.model import MorphableModel

__all__ = [
    "COLOUR_SPACES", "COLOUR_SPACE_KEY", "ColourSpace", "check_colour_space",
    "colour_space_metadata", "decode_texture", "encode_texture", "model_colour_space",
    "resolve_colour_space",
]

#: The values a model's colour space can take.
COLOUR_SPACES = ("linear", "srgb")

#: Metadata key naming the colour space (``MorphableModel.metadata``).
COLOUR_SPACE_KEY = "colour_space"

#: What :func:`colour_space_metadata` writes for each value.
_METADATA_TEXT = {"linear": "linear sRGB", "srgb": "sRGB (gamma-encoded)"}

#: ``metadata["source_format"]`` of a colour-only model read from a scalismo MoMo file.
_MOMO_SOURCE = "scalismo MoMo HDF5"

#: ``source_format`` of files written elsewhere: their ``colour_space`` entry is the reader's
#: guess from the layout (:mod:`albedo_model.io.momo_h5`), not something the file says.
_FOREIGN_SOURCES = (_MOMO_SOURCE, "AlbedoMM HDF5")

_LABELS = {
    "linear": "linear albedo, linear sRGB",
    "srgb": "gamma-encoded sRGB texture, camera values",
}


@dataclass(frozen=True)
class ColourSpace:
    """The resolved colour space of a model's colour parts.

    Attributes
    ----------
    value : {"linear", "srgb"}
    source : str
        Where the value came from: ``"override"``, ``"model metadata"``,
        ``"layout default"`` or ``"default"``.
    label : str
        A human description, e.g. ``"gamma-encoded sRGB texture, camera values"``.
    """

    value: str
    source: str
    label: str

    @property
    def is_srgb(self) -> bool:
        """Whether the model's colour is a gamma-encoded sRGB texture."""
        return self.value == "srgb"

    def describe(self) -> str:
        """One line: ``"srgb (gamma-encoded sRGB texture ...; from model metadata)"``."""
        return f"{self.value} ({self.label}; from {self.source})"


def check_colour_space(value: str | None, what: str = "model colour") -> str | None:
    """Return ``value`` if it is None, ``"linear"`` or ``"srgb"``; InputError otherwise.

    Parameters
    ----------
    value : str or None
    what : str
        The setting's name in the error message.
    """
    if value is None or value in COLOUR_SPACES:
        return value
    raise InputError(f"{what} must be 'linear' or 'srgb', got {value!r}")


def _from_metadata(text: str) -> str | None:
    """Colour space named by a metadata value, or None when it says nothing about the encoding."""
    t = " ".join(str(text).lower().replace("_", " ").replace("-", " ").split())
    if t.startswith("linear"):
        return "linear"
    if t.startswith("srgb") or "gamma encoded" in t or t in ("encoded", "gamma"):
        return "srgb"
    return None


def model_colour_space(model: MorphableModel, override: str | None = None) -> ColourSpace:
    """Resolve the colour space of ``model``'s colour parts.

    Parameters
    ----------
    model : MorphableModel
    override : {"linear", "srgb"}, optional
        Wins over everything the model says.

    Returns
    -------
    ColourSpace

    Raises
    ------
    InputError
        ``override`` is neither None, ``"linear"`` nor ``"srgb"``.

    Notes
    -----
    The rules are listed in the module docstring
    (:func:`resolve_colour_space` of the model's metadata and parts).
    """
    return resolve_colour_space(model.metadata, has_specular=model.specular is not None,
                                override=override)


def resolve_colour_space(metadata: Mapping[str, str] | None, *, has_specular: bool,
                         override: str | None = None) -> ColourSpace:
    """Resolve a colour space from a model's metadata and layout (files not read as models too).

    Parameters
    ----------
    metadata : mapping of str to str, or None
        The model's (or albedo part's) metadata.
    has_specular : bool
        Whether the colour is split into diffuse and specular parts (AlbedoMM).
    override : {"linear", "srgb"}, optional

    Returns
    -------
    ColourSpace
    """
    if check_colour_space(override, "--model-colour") is not None:
        return ColourSpace(override, "override", _LABELS[override])
    metadata = metadata or {}
    named = _from_metadata(metadata.get(COLOUR_SPACE_KEY, ""))
    if named is not None and metadata.get("source_format") not in _FOREIGN_SOURCES:
        return ColourSpace(named, "model metadata", _LABELS[named])
    if has_specular:
        return ColourSpace("linear", "layout default",
                           _LABELS["linear"] + ", as AlbedoMM's diffuse/specular albedo")
    if metadata.get("source_format") == _MOMO_SOURCE:
        return ColourSpace("srgb", "layout default",
                           _LABELS["srgb"] + ", as BFM 2017's colour-only model")
    return ColourSpace("linear", "default", _LABELS["linear"] + ", nothing says otherwise")


def colour_space_metadata(value: str) -> dict[str, str]:
    """Return the metadata entry that makes :func:`model_colour_space` read ``value``.

    Parameters
    ----------
    value : {"linear", "srgb"}

    Returns
    -------
    dict
        ``{"colour_space": "linear sRGB"}`` or ``{"colour_space": "sRGB (gamma-encoded)"}``.
    """
    if check_colour_space(value, "colour space") is None:
        raise InputError("colour space must be 'linear' or 'srgb', got None")
    return {COLOUR_SPACE_KEY: _METADATA_TEXT[value]}


def _float_result(values: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out`` in ``values``' dtype when that is float32, float64 otherwise."""
    return out.astype(np.float32 if values.dtype == np.float32 else np.float64, copy=False)


def decode_texture(values: np.ndarray) -> np.ndarray:
    """Decode gamma-encoded sRGB texture values to linear values (the IEC 61966-2-1 EOTF).

    Parameters
    ----------
    values : (...,) float array
        Encoded values, nominally in [0, 1]; values outside are decoded by the
        same curve (its linear segment below 0.04045, sign kept), not clipped.

    Returns
    -------
    (...,) float array
        Linear values, float32 for float32 input, float64 otherwise (a new array).
    """
    import colour

    x = np.asarray(values)
    return _float_result(x, np.asarray(colour.cctf_decoding(x, function="sRGB")))


def encode_texture(values: np.ndarray) -> np.ndarray:
    """Encode linear values as sRGB texture values (the inverse of :func:`decode_texture`).

    Parameters
    ----------
    values : (...,) float array
        Linear values, nominally in [0, 1] (not clipped).

    Returns
    -------
    (...,) float array
        Encoded values, float32 for float32 input, float64 otherwise (a new array).
    """
    import colour

    x = np.asarray(values)
    return _float_result(x, np.asarray(colour.cctf_encoding(x, function="sRGB")))
