"""What a :class:`~albedo_model.render.renderer.Renderer` caches per scene.

:class:`RenderState` holds, for one set of scene parameters, the host instance,
the ray-cast buffers, and the device arrays of every stage down to the
per-pixel attributes the shader reads (the stages themselves are in
:mod:`albedo_model.render.stages`), with the version stamps of its parameter
blocks (:mod:`albedo_model.render.cache_table`).

The per-pixel attributes are :class:`Deferred`: computed when first read.
XLA-CPU compiles a program with many per-pixel outputs into about one loop
per output (35 for the pixel attributes of a ray cast), while what feeds a
single reduction fuses into a few loops; :func:`~albedo_model.render.stages.image_stage`
therefore evaluates what a proposal changed inside the likelihood's own program
and writes nothing out.

This module imports :mod:`albedo_model.params`, :mod:`albedo_model.render.cache_table`,
:mod:`albedo_model.render.raycast` and :mod:`albedo_model.shading.effects`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from albedo_model.params import RenderParameter
from albedo_model.render.cache_table import BlockVersions
from albedo_model.render.raycast import RayHits
from albedo_model.shading.effects import Effects

__all__ = ["RenderState", "Rendered", "HostAlbedo", "Deferred"]


class HostAlbedo:
    """Host copy of a state's device albedo, made on first access (the hot path never needs it).

    Parameters
    ----------
    device : (rows, 3n) float32 device array
        Diffuse albedo (row 0) and, with two rows, specular albedo (row 1).
    host : (rows, 3n) float32 array, optional
        The same values on the host, when already at hand.
    """

    def __init__(self, device, host: np.ndarray | None = None):
        self.device = device
        self._host = None
        if host is not None:
            host = host.view()
            host.flags.writeable = False
            self._host = (host, host[0], host[1] if len(host) > 1 else None)

    @property
    def array(self) -> np.ndarray:
        """(rows, 3n) float32, read-only."""
        if self._host is None:
            host = np.array(self.device)
            host.flags.writeable = False
            self._host = (host, host[0], host[1] if len(host) > 1 else None)
        return self._host[0]

    @property
    def diffuse(self) -> np.ndarray:
        """Diffuse albedo (row 0) as a (3n,) float32 view, read-only."""
        self.array
        return self._host[1]

    @property
    def specular(self) -> np.ndarray | None:
        """Specular albedo (row 1) as a (3n,) float32 view, or None with one row."""
        self.array
        return self._host[2]


class Deferred:
    """One per-pixel cache of a render state, computed when first needed.

    Holds a :class:`~albedo_model.shading.interpolation.PixelHits`, ``PixelGeometry``,
    ``PixelAlbedo`` or :class:`~albedo_model.shading.image_formation.PixelLight`:
    reading an attribute (``.normal``, ``.diffuse``, ...) or :attr:`value` computes it
    once (a write-once memo: the value is a pure function of ``inputs``).
    :meth:`Renderer.compose <albedo_model.render.renderer.Renderer.compose>` instead
    evaluates a value that the state being evaluated created itself (``stamp``
    equal to the state's, not yet computed) inside the likelihood's program
    (:func:`image_stage`), without storing it: a rejected proposal never writes
    its pixel attributes out, and an accepted one computes them when a later
    step, whose state shares them, reads them.

    Parameters
    ----------
    stage : callable
        ``stage(**inputs) -> value``, with Deferred inputs replaced by their values.
    inputs : dict
        Arrays (and Deferred values) the value is computed from; the fused
        programs read these instead of the value.
    effects : Effects
        The effect set the value is computed for.
    stamp : int
        The stamp of the render state that created it (:attr:`RenderState.stamp`).
    """

    __slots__ = ("_stage", "_value", "effects", "inputs", "stamp")

    def __init__(self, stage, inputs: dict, effects: Effects, stamp: int = 0):
        self._stage, self._value = stage, None
        self.inputs, self.effects, self.stamp = inputs, effects, int(stamp)

    @property
    def computed(self) -> bool:
        """True once the value has been computed and stored."""
        return self._value is not None

    @property
    def value(self):
        """The computed NamedTuple of device arrays."""
        if self._value is None:
            args = {k: v.value if isinstance(v, Deferred) else v for k, v in self.inputs.items()}
            self._value = self._stage(**args)
        return self._value

    def __getattr__(self, name: str):
        """Read a field of the value (computing it first); private names are not forwarded."""
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.value, name)


class RenderState(NamedTuple):
    """Everything cached for one set of scene parameters (host and device arrays).

    Attributes
    ----------
    params : RenderParameter
    shape : (3n,) float32, host
        Shape + expression instance, interleaved (model frame, mm).
    vertices : (n, 3) float32 device array, model frame
    normals : three (n,) float32 device arrays, model frame (unit vertex normals)
    albedo_dev : (1, 3n) or (2, 3n) float32 device array
        Diffuse albedo (row 0) and, when the renderer shades it, specular albedo
        (row 1), interleaved per vertex. Block updates happen on the device.
    host_albedo : HostAlbedo
        Its host copy, made when first read (properties ``albedo``, ``diffuse``,
        ``specular``: (rows, 3n) and (3n,) float32 host arrays, specular None
        when not rendered).
    hits : RayHits
        Host ray-cast buffers of every pixel (row-major).
    prim_id : (P,) int32, bary : (P, 2) float32
        The hits' buffers (host arrays; the device works on ``pixel_hits``).
    geometry_pending : bool
        True when the state's geometry lives in the renderer's spare scene
        (a proposal not yet accepted).
    pixel_hits : Deferred PixelHits
        Corner vertex ids and barycentric weights of every pixel, device.
    pixel_geometry : Deferred PixelGeometry
        Per-pixel world normals (and view directions), device.
    pixel_albedo : Deferred PixelAlbedo
        Per-pixel diffuse (and specular) albedo, device.
    pixel_light : Deferred PixelLight
        Per-pixel light transport (everything of the image but the albedo), device.
        The four are computed when first read (:class:`Deferred`).
    effects : Effects
        The renderer's effect set for ``params``.
    shading : (PACKED_SIZE,) float32, host
        Packed shading parameters of ``params`` (:func:`albedo_model.shading.image_formation.pack_shading_params`).
    updates : (int, int)
        Incremental block updates behind the shape and the albedo instances
        since they were last computed in full (see :mod:`albedo_model.render.instances`).
    pixels : (C,) int32 host array, or None
        The pixel set the per-pixel caches hold, as row-major pixel indices
        (sorted): every pixel whose ray hit, plus misses up to a bucketed size
        (so that compiled programs see few distinct shapes). None: every pixel.
        The caches' ``(P,)`` arrays above are then ``(C,)``; :meth:`full`
        expands one to the image, and the shading stages return whole images.
    pixels_dev : device copy of ``pixels`` (or None)
    versions : BlockVersions
        One version stamp per parameter block (:mod:`albedo_model.render.cache_table`):
        caches of products of this state are keyed on the stamps of the blocks
        their stage reads.
    stamp : int
        A stamp of this state alone (new for every :meth:`Renderer.update
        <albedo_model.render.renderer.Renderer.update>`); the per-pixel caches it
        created carry it.
    shadow : (key, (C,) float32 array) or None
        The directional light's visibility at the pixel set (cast shadows) and
        the ``stage_key`` of the ``shadow`` stage it was cast for: an SH light or
        colour move reuses it, a light-direction move re-casts only these rays.
        None without cast shadows.
    """

    params: RenderParameter
    shape: np.ndarray
    vertices: object
    normals: tuple
    albedo_dev: object
    host_albedo: HostAlbedo
    hits: RayHits
    prim_id: np.ndarray
    bary: np.ndarray
    geometry_pending: bool
    pixel_hits: Deferred
    pixel_geometry: Deferred
    pixel_albedo: Deferred
    pixel_light: Deferred
    effects: Effects
    shading: np.ndarray
    updates: tuple[int, int] = (0, 0)
    pixels: np.ndarray | None = None
    pixels_dev: object = None
    versions: BlockVersions | None = None
    stamp: int = 0
    shadow: tuple | None = None

    def positions(self, indices: np.ndarray) -> np.ndarray:
        """Where pixels (row-major indices, all in the pixel set) sit in the caches' arrays."""
        idx = np.asarray(indices)
        return idx if self.pixels is None else np.searchsorted(self.pixels, idx)

    def full(self, values, fill=0.0) -> np.ndarray:
        """Per-pixel ``values`` of the state's pixel set as a whole image (host, row-major).

        Parameters
        ----------
        values : (C,) or (C, k) array (host or device)
            One value per entry of :attr:`pixels` (e.g. a channel of a pixel cache).
        fill : scalar
            Value of the pixels outside the set (all misses).

        Returns
        -------
        (H W,) or (H W, k) numpy array; ``values`` itself when the set is every pixel.
        """
        v = np.asarray(values)
        if self.pixels is None:
            return v
        w, h = self.params.image_size
        out = np.full((int(w) * int(h),) + v.shape[1:], fill, v.dtype)
        out[self.pixels] = v
        return out

    @property
    def albedo(self) -> np.ndarray:
        """(rows, 3n) float32 host copy of ``albedo_dev``."""
        return self.host_albedo.array

    @property
    def diffuse(self) -> np.ndarray:
        """(3n,) float32 host diffuse albedo instance."""
        return self.host_albedo.diffuse

    @property
    def specular(self) -> np.ndarray | None:
        """(3n,) float32 host specular albedo instance, None when not rendered."""
        return self.host_albedo.specular


class Rendered(NamedTuple):
    """A rendered image.

    Attributes
    ----------
    image : (H, W, 3) float32, linear or gamma-encoded as requested
    mask : (H, W) bool, True on the face (alpha 1)
    state : RenderState, the buffers behind the image
    """

    image: np.ndarray
    mask: np.ndarray
    state: RenderState
