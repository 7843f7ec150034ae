"""The phase that chooses a fit's light effects, between the first climb and the Laplace approximation.

:class:`EffectPhases` is a mixin of :class:`~mcmcfit.fitting.chain_session.ChainSession`:
the driver (:func:`mcmcfit.fitting.driver.drive_chains`) calls :meth:`~EffectPhases.choose_effects`
on every chain after the climbs, takes the best chain's decision and hands it
to every chain with :meth:`~EffectPhases.set_effects`, so that all chains sample
one posterior. With the directional light on, each chain starts it from its own
evidence (:func:`~mcmcfit.fitting.effects_choice.with_directional`) and the
rounds of climbs that follow polish it with cast shadows.

With a robust foreground, the pixels more likely an occluder than the face at
the mode are left out of the evidence.

This module imports :mod:`mcmcfit.fitting` (effects_choice, gaussian_stage),
:mod:`mcmcfit.sampling.kernel` and :mod:`mcmcfit.targets.robust_foreground`.
"""

from __future__ import annotations

import math
import time

import numpy as np

from mcmcfit.fitting.effects_choice import SCREEN_RATIO, directional_evidence, with_directional
from mcmcfit.fitting.gaussian_stage import sampling_coordinates
from mcmcfit.sampling.kernel import init
from mcmcfit.targets.robust_foreground import face_weights

__all__ = ["EffectPhases"]

#: A start for a directional light that ``--effects sh+directional`` forces where the
#: evidence found none: from the upper front, a third of the SH light's strength.
FORCED_START = {"azimuth_deg": 0.0, "elevation_deg": 30.0, "strength": [0.3, 0.3, 0.3]}


class EffectPhases:
    """Choose the image model's light effects at the mode (a mixin; see the module notes).

    Reads the session's ``cfg``, ``mode``, ``posterior`` and ``_measure``, and
    sets ``mode``, ``coords`` and ``state`` when the directional light is switched on.
    """

    _evidence: dict | None = None

    def choose_effects(self) -> dict:
        """Return this chain's decision: ``decision`` ("sh" or "sh+directional"), ``reason``, ``evidence``."""
        cfg = self.cfg
        if cfg.effects == "sh":
            return {"decision": "sh", "reason": "set by --effects sh"}
        if cfg.sampler != "gaussian":
            return {"decision": "sh",
                    "reason": f"the {cfg.sampler} sampler has no directional-light moves"}
        t0 = time.perf_counter()
        region, noise = self._measure(self.mode.params)
        if noise.outlier_probability > 0.0:  # robust: what looks occluded is no evidence of light
            region = region & ~self._occluded(self.mode.params, region, noise)
        ev = directional_evidence(self.posterior.renderer, self.posterior.image_target.linear,
                                  self.mode.params, region, noise.sigma, noise.temperature)
        ev["seconds"] = time.perf_counter() - t0
        self._evidence = ev
        shown = {k: v for k, v in ev.items() if k != "sh"}
        if cfg.effects == "sh+directional":
            return {"decision": "sh+directional", "reason": "set by --effects sh+directional",
                    "evidence": shown}
        if ev.get("first_pass_ratio", 1.0) < SCREEN_RATIO:
            reason = (f"the best directional light is weak ({ev['first_pass_ratio']:.2f} of the "
                      f"ambient shading, screen {SCREEN_RATIO}): no shadow ray cast")
        elif ev["on"]:
            reason = (f"a directional light explains the photograph better by "
                      f"{ev['gain']:.0f} nats (threshold {ev['threshold']:.0f})")
        elif math.isfinite(ev["threshold"]):
            reason = (f"a directional light gains {ev['gain']:.0f} nats, under the "
                      f"threshold of {ev['threshold']:.0f}")
        else:
            reason = "no directional light with positive strength improves the fit"
        return {"decision": "sh+directional" if ev["on"] else "sh", "reason": reason,
                "evidence": shown}

    def _occluded(self, params, region, noise):
        """Region pixels the robust foreground thinks more likely an occluder than the face (H W,)."""
        lik = self._region_posterior(region, noise).face.image_likelihood  # the fit's own
        out = self.posterior.renderer.render(params)
        pix = np.flatnonzero(np.asarray(region, bool).reshape(-1))
        face = face_weights(lik, pix, np.asarray(out.image, np.float64).reshape(-1, 3)[pix],
                            lik.target.linear.reshape(-1, 3)[pix])
        occluded = np.zeros(np.size(region), bool)
        occluded[pix] = face < 0.5
        return occluded.reshape(np.shape(region))

    def set_effects(self, decision: str) -> bool:
        """Switch the directional light on when ``decision`` says so; return whether it is on."""
        if decision != "sh+directional":
            return False
        ev = self._evidence or {}
        start = ev if "azimuth_deg" in ev else dict(
            FORCED_START, sh=self.mode.params.environment_map.coefficients)
        params = with_directional(self.mode.params, start)
        self.mode = self.mode._replace(params=params)
        self.coords = sampling_coordinates(params)
        self.state = init(params, self.posterior.face, image=True)
        return True
