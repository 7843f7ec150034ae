"""A chain's draws after the climb: kept draws, draws in coordinates, re-centring, widening.

:class:`DrawPhases` is a mixin of both chain sessions, a single fit's
(:class:`~mcmcfit.fitting.chain_session.ChainSession`) and a joint fit's
(:class:`~mcmcfit.fitting.joint_session.JointChainSession`).

This module imports :mod:`albedo_model.errors`, :mod:`mcmcfit.fitting.mode`,
:mod:`mcmcfit.sampling` (chain, kernel) and :mod:`proposals.laplace.widening`.
"""

from __future__ import annotations

import time

import numpy as np

from albedo_model.errors import InputError
from mcmcfit.fitting.mode import ADOPT_GAP, POLISH_STEPS
from mcmcfit.sampling.chain import ChainRecord, ChainRecorder
from mcmcfit.sampling.kernel import init, run
from proposals.laplace.widening import widened_by_draws, widened_by_fisher

__all__ = ["DrawPhases"]


class DrawPhases:
    """A chain's draws: kept draws, draws in coordinates, re-centring and widening (a mixin).

    Reads the session's ``problem``, ``cfg``, ``rng``, ``state``, ``proposal``,
    ``chain_target`` (the target its chain runs on), ``coords``, ``mode``, ``approx``,
    ``_warm``, ``_kept`` (recorders) and ``_t_warm``, ``_t_kept``, and calls its
    ``_check``, ``_build_proposal``, ``_climb``, ``_climb_posterior``,
    ``_coordinate_gradient`` and ``_approximate``: shared by a single fit's
    (:class:`~mcmcfit.fitting.chain_session.ChainSession`) and a joint fit's
    (:class:`~mcmcfit.fitting.joint_session.JointChainSession`) sessions.
    """

    def draw(self, n_steps: int) -> ChainRecord:
        """Run ``n_steps`` kept steps (continuing the chain) and return the kept record so far."""
        if self._kept is None:
            self._kept = ChainRecorder(self.problem.layout, 0, self.cfg.thin, self.state,
                                       stage="image")
        self._advance(self._kept, n_steps)
        return self._kept.record(self._t_kept)

    def _advance(self, recorder: ChainRecorder, n: int) -> None:
        """Run ``n`` steps of the chain on ``self.chain_target``, recorded (and checked)."""
        offset = recorder.steps_done
        recorder.extend(n)
        check = self._check()
        t0 = time.perf_counter()

        def callback(i, s, info):
            recorder(offset + i, s, info)
            if check is not None:
                check(offset + i, s, info)

        self.state = run(self.rng, self.state, self.chain_target, self.proposal, n, image=True,
                         callback=callback)
        dt = time.perf_counter() - t0
        if recorder is self._warm:
            self._t_warm += dt
        else:
            self._t_kept += dt

    def warmup_draws(self, fraction: float = 0.5) -> np.ndarray:
        """Return the last ``fraction`` of the warm-up's draws in sampling coordinates (n, d)."""
        return self._draws_of(self._warm, fraction)

    def kept_draws(self, fraction: float = 0.75) -> np.ndarray:
        """Return the last ``fraction`` of the kept draws so far in sampling coordinates (n, d)."""
        return self._draws_of(self._kept, fraction)

    def _draws_of(self, recorder, fraction: float) -> np.ndarray:
        if recorder is None or self.coords is None:
            return np.zeros((0, 0 if self.coords is None else self.coords.size))
        rec = recorder.record()
        tail = rec.samples[int(rec.samples.shape[0] * (1.0 - fraction)):]
        layout, base = self.problem.layout, self.mode.params
        return np.array([self.coords.u_of(layout.from_vector(v, base)) for v in tail])

    def restart_kept(self) -> int:
        """Make the kept draws so far warm-up (the sampler is about to change); return their number.

        The next :meth:`draw` starts a new kept chain from the current state.
        """
        if self._kept is None:
            return 0
        n = self._kept.steps_done
        if self._warm is None:
            self._warm, self._t_warm = self._kept, self._t_kept
            self._warm.stage = "warmup"
        else:
            self._warm.absorb(self._kept)
            self._t_warm += self._t_kept
        self._kept, self._t_kept = None, 0.0
        return n

    def recentre(self, gap: float = ADOPT_GAP) -> dict:
        """Climb again from the warm-up's best draw if it beats the mode; refit the approximation.

        A climb can stop short on a long, bent ridge (a damped Levenberg-Marquardt
        step gains little, so it ends; `mcmcfit demo --seed 2` stopped 240 nats
        below the posterior's peak, 20 sds along the distance), and every
        Gaussian move then proposes around the wrong point. The warm-up's chain
        finds the higher ground; when its best draw beats the mode by more than
        ``gap`` nats, the chain climbs from that draw and the Laplace approximation
        and the moves are rebuilt at the new mode. The target (region, noise model)
        and the chain's state are unchanged, so this is warm-up adaptation only.

        Returns
        -------
        dict
            ``gain``: the warm-up's best log posterior minus the mode's (nats);
            ``moved``: whether the chain climbed and re-centred; then ``log_density``,
            the new mode's (in sampling coordinates).
        """
        if self._warm is None or self.approx is None:
            return {"moved": False, "gain": None}
        target = self.chain_target
        best = self._warm.best_posterior
        at_mode = init(self.mode.params, target, image=True).log_posterior
        gain = float(best.log_posterior - at_mode)
        out = {"moved": False, "gain": gain}
        if gain > gap:
            self.mode = self._climb(self._climb_posterior(), best.params, self.cfg.mode_steps,
                                    polish=POLISH_STEPS)
            self._approximate()
            out.update(moved=True, log_density=float(self.mode.log_density))
        # the renders of the mode (and the climb) moved the renderer's scene: restore the chain's
        self.state = init(self.state.params, target, image=True)
        return out

    def warmup_gradients(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Return the last ``n`` warm-up draws and the posterior's gradient at each, in coordinates.

        One exact gradient per draw (a ray cast and a reverse pass, ~30 ms at
        250^2), for :meth:`widen` with ``gradients``. Returns two (k, d) arrays,
        k <= n: a draw whose gradient fails or is not finite is left out.
        """
        rec = self._warm.record() if self._warm is not None else None
        if rec is None or self.coords is None or self.approx is None or n < 1:
            size = 0 if self.coords is None else self.coords.size
            return np.zeros((0, size)), np.zeros((0, size))
        grad = self._coordinate_gradient()
        layout, base = self.problem.layout, self.mode.params
        draws, grads = [], []
        for v in rec.samples[-n:]:
            params = layout.from_vector(v, base)
            try:
                g = np.asarray(grad(params)[1], np.float64)
            except (InputError, ValueError, ArithmeticError):
                continue
            if np.all(np.isfinite(g)):
                draws.append(self.coords.u_of(params))
                grads.append(g)
        size = self.coords.size
        return np.array(draws).reshape(-1, size), np.array(grads).reshape(-1, size)

    def widen(self, draws: list[np.ndarray], effective_fraction: float = 0.25,
              gradients: list[np.ndarray] | None = None) -> dict:
        """Widen the Gaussian approximation where warm-up ``draws`` (one array per chain) are wider.

        See :func:`proposals.laplace.widening.widened_by_draws`, or with
        ``gradients`` (the log density's gradient at each draw, as
        :meth:`warmup_gradients` returns them)
        :func:`~proposals.laplace.widening.widened_by_fisher`; the moves are
        rebuilt on the widened approximation (their step multipliers are
        adapted again by the rest of the warm-up).

        Returns
        -------
        dict
            ``ratios`` (variance ratios of the widened directions), ``largest``
            (largest whitened eigenvalue), ``edge`` (the noise edge, or the
            Fisher estimate's threshold), ``n_draws``.
        """
        if self.approx is None:
            return {"ratios": [], "largest": None, "edge": None, "n_draws": 0}
        if gradients is None:
            found = widened_by_draws(self.approx, [np.asarray(d) for d in draws],
                                     effective_fraction=effective_fraction)
        else:
            found = widened_by_fisher(self.approx, [np.asarray(d) for d in draws],
                                      [np.asarray(g) for g in gradients])
        self.approx = found.approx
        self._build_proposal()
        return {"ratios": [float(r) for r in found.ratios], "largest": found.largest,
                "edge": found.edge, "n_draws": found.n_draws}
