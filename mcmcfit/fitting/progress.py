"""A tqdm progress bar for :func:`mcmcfit.fitting.fit.fit` on stderr (stage, chain, steps).

This module imports nothing from the project; tqdm is imported when a bar is
first drawn.
"""

from __future__ import annotations

import sys

__all__ = ["FitProgressBar"]

_STAGE_NAMES = {"landmarks": "landmark stage", "image": "image stage"}


class FitProgressBar:
    """Progress callback ``(stage, chain, done, total)`` drawing one bar per stage.

    The chains run in lockstep (:func:`mcmcfit.fitting.fit.fit` reports every
    chain after each round), so one bar per stage shows them all: ``chain 1/1``
    for one chain, ``chains 1-K`` for several, at the steps the slowest
    reported chain has done. (A bar per chain, replaced whenever another chain
    reported, restarted from 0 % with a meaningless rate after every round in a
    log file.)

    Parameters
    ----------
    chains : int
        Number of chains (shown as ``chain i/K``).
    disable : bool
        Draw nothing (``--quiet``).
    file : text stream
        Where the bar goes (stderr by default).

    Examples
    --------
    >>> with FitProgressBar(2) as bar:                  # doctest: +SKIP
    ...     fit(image, landmarks, model, progress=bar)
    """

    def __init__(self, chains: int, *, disable: bool = False, file=None):
        self.chains = int(chains)
        self.disable = bool(disable)
        self.file = file if file is not None else sys.stderr
        self._bar = None
        self._key = None
        self._done: dict[int, int] = {}

    def __call__(self, stage: str, chain: int, done: int, total: int) -> None:
        """Advance the bar of ``(stage, chain)`` to ``done`` of ``total`` steps."""
        if self.disable:
            return
        from tqdm import tqdm

        key = (stage, total)
        if key != self._key:
            self.close()
            who = "chain 1/1" if self.chains == 1 else f"chains 1-{self.chains}"
            desc = f"{who} {_STAGE_NAMES.get(stage, stage)}"
            self._bar = tqdm(total=total, desc=desc, unit="step", file=self.file,
                             dynamic_ncols=True, leave=True)
            self._key = key
            self._done = {}
        self._done[chain] = done
        slowest = min(self._done.values()) if len(self._done) >= self.chains else 0
        self._bar.update(max(0, slowest - self._bar.n))
        if slowest >= total:  # finished: do not let the bar's clock run on through the outputs
            self.close()

    def close(self) -> None:
        """Close the current bar (idempotent)."""
        if self._bar is not None:
            self._bar.close()
        self._bar = None
        self._key = None

    def __enter__(self) -> FitProgressBar:
        """Return the callback itself (the bar is closed on exit)."""
        return self

    def __exit__(self, *exc) -> None:
        """Close the current bar; exceptions propagate."""
        self.close()
