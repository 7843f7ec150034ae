"""A tqdm progress bar for :func:`mcmcfit.fitting.fit.fit` on stderr (stage, chain, steps).

This module imports nothing from the project; tqdm is imported when a bar is
first drawn.
"""

from __future__ import annotations

import sys

__all__ = ["FitProgressBar"]

_STAGE_NAMES = {"landmarks": "landmark stage", "image": "image stage"}


class FitProgressBar:
    """Progress callback ``(stage, chain, done, total)`` drawing one bar per stage and chain.

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

    def __call__(self, stage: str, chain: int, done: int, total: int) -> None:
        """Advance the bar of ``(stage, chain)`` to ``done`` of ``total`` steps."""
        if self.disable:
            return
        from tqdm import tqdm

        key = (stage, chain)
        if key != self._key:
            self.close()
            desc = f"chain {chain + 1}/{self.chains} {_STAGE_NAMES.get(stage, stage)}"
            self._bar = tqdm(total=total, desc=desc, unit="step", file=self.file,
                             dynamic_ncols=True, leave=True)
            self._key = key
        self._bar.update(max(0, done - self._bar.n))
        if done >= total:  # finished: do not let the bar's clock run on through the outputs
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
