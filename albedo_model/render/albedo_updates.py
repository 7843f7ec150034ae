"""Albedo instances on the device, updated by coefficient-block deltas.

An albedo move changes a block of about ten shared coefficients: the device
instance moves by the changed rows of the transposed scaled basis
(:func:`~albedo_model.render.stages.albedo_delta_stage`) instead of a full
product; a large change, or every ``refresh_every``-th update
(:mod:`albedo_model.render.instances`), recomputes it on the host in float64.

This module imports :mod:`albedo_model.params`, :mod:`albedo_model.render.instances`,
:mod:`albedo_model.render.stages` and :mod:`albedo_model.render.state`.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from albedo_model.params import RenderParameter
from albedo_model.render.instances import ModelInstances
from albedo_model.render.stages import albedo_delta_stage
from albedo_model.render.state import HostAlbedo, RenderState

__all__ = ["DeviceAlbedo"]


class DeviceAlbedo:
    """Block updates of a render state's device albedo.

    Parameters
    ----------
    instances : ModelInstances
        The renderer's instances (the plan of each update, the host recompute).
    """

    def __init__(self, instances: ModelInstances):
        self.instances = instances
        self._basis = None  # device (k, rows * 3n) transposed albedo basis, on first use

    def update(self, state: RenderState, params: RenderParameter):
        """Return None when nothing changed, else ``(albedo_dev, host copy, update count)``.

        Parameters
        ----------
        state : RenderState
            The state the move starts from.
        params : RenderParameter
            The moved parameters.
        """
        inst = self.instances
        plan = inst.albedo_plan(state.params, params, state.updates[1])
        if plan is None:
            return None
        if isinstance(plan, str):
            host = inst.albedo(params)
            albedo_dev = jnp.asarray(host)
            return albedo_dev, HostAlbedo(albedo_dev, host), 0
        idx, delta = plan
        if self._basis is None:
            self._basis = jnp.asarray(inst.updater.transposed(inst.albedo_parts))
        # one compile per block size up to 16 (a sampler uses a few fixed sizes); beyond,
        # pad to a power of two (repeating a row with zero weight) to bound recompiles
        size = len(idx) if len(idx) <= 16 else 1 << int(np.ceil(np.log2(len(idx))))
        idx = np.concatenate([idx, np.full(size - len(idx), idx[0], np.int32)])
        delta = np.concatenate([delta, np.zeros(size - len(delta), np.float32)])
        albedo_dev = albedo_delta_stage(state.albedo_dev, self._basis, idx, delta)
        return albedo_dev, HostAlbedo(albedo_dev), state.updates[1] + 1
